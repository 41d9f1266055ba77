"""A teammate's circular base seen as an ellipse -> its two candidate poses (seed 003,
003_8db27855ce2d5f68.txt, section II, eqs. 1-4): `circle_candidates`, a `CandidateSet` of
target_T_sensor poses with their covariance (centre from the ellipse's accuracy, the normal's
tilt `normal_sigma`, the unobservable yaw `yaw_sigma`).
"""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.candidates import CandidateSet
from graphloc.vision.circle import circles_from_cones, rotations_from_normals
from graphloc.vision.ellipse import ellipse_to_conic


def centre_covariance(
    centre: np.ndarray,
    camera: PinholeCamera,
    radius: float,
    centre_sigma_px: float,
    radius_sigma_px: float,
) -> np.ndarray:
    """(3,3) covariance [m^2] of a circle centre `centre` (camera frame) whose image has its
    centre known to `centre_sigma_px` and its radius to `radius_sigma_px`: depth sigma
    z sigma_r / r_px along the line of sight, lateral sigma z sigma_c / f across it."""
    z = float(centre[2])
    r_px = camera.fx * radius / z
    f = 0.5 * (camera.fx + camera.fy)
    d = centre / np.linalg.norm(centre)
    along = np.outer(d, d)
    return (z * centre_sigma_px / f) ** 2 * (np.eye(3) - along) + (
        z * radius_sigma_px / r_px
    ) ** 2 * along


def circle_candidates(
    camera: PinholeCamera,
    ellipse,
    radius: float,
    centre_sigma_px: float,
    radius_sigma_px: float,
    normal_sigma: float,
    yaw_sigma: float,
    time: float = 0.0,
    observer: str = "",
    observed: str = "",
) -> CandidateSet:
    """Ellipse (u0, v0, width, height, angle deg) in ideal pixels of `camera` and the circle's
    radius [m] -> the 2 candidate poses target_T_sensor (target frame: origin the circle centre,
    z its normal towards the camera, `rotations_from_normals`) with covariances (2,6,6).
    ValueError when the ellipse is not the image of a circle in front of the camera."""
    e = np.asarray(ellipse, dtype=float).reshape(5)
    if not (np.isfinite(e).all() and e[2] > 0 and e[3] > 0):
        raise ValueError(f"ellipse {e.tolist()}: needs finite values and width, height > 0")
    for name, v in (
        ("radius", radius),
        ("centre_sigma_px", centre_sigma_px),
        ("radius_sigma_px", radius_sigma_px),
        ("normal_sigma", normal_sigma),
        ("yaw_sigma", yaw_sigma),
    ):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"circle_candidates: {name} must be finite > 0, got {v}")
    K = camera.K
    cone = K.T @ ellipse_to_conic(e[None])[0] @ K
    centres, normals, ok = circles_from_cones(cone[None], float(radius))
    if not ok[0]:
        raise ValueError(f"ellipse {e.tolist()}: not the image of a circle (no real cone)")
    R = rotations_from_normals(normals[0])  # (2,3,3) sensor_R_target
    cov = np.zeros((2, 6, 6))
    poses = []
    for j in range(2):
        X = gtsam.Pose3(gtsam.Rot3(R[j]), centres[0, j])  # sensor_T_target
        sigma = np.zeros((6, 6))  # right perturbation of sensor_T_target (target frame)
        sigma[:3, :3] = np.diag([normal_sigma**2, normal_sigma**2, yaw_sigma**2])
        C = centre_covariance(centres[0, j], camera, radius, centre_sigma_px, radius_sigma_px)
        sigma[3:, 3:] = R[j].T @ C @ R[j]
        A = X.AdjointMap()  # X^-1 exp(-Ad_X xi): the covariance of target_T_sensor
        cov[j] = A @ sigma @ A.T
        poses.append(X.inverse())
    return CandidateSet(
        np.stack([p.rotation().matrix() for p in poses]),
        np.stack([p.translation() for p in poses]),
        np.ones(2),
        time,
        observer,
        observed,
        "circle",
        meta={
            "radius": float(radius),
            "centre_sigma_px": float(centre_sigma_px),
            "radius_sigma_px": float(radius_sigma_px),
        },
        covariance=0.5 * (cov + cov.transpose(0, 2, 1)),
    )
