"""Pose of a circle of known radius from its image ellipse (seed 003, section II-A "Robot
Tracker": 1) ellipse fit to edge points, `vision.ellipse`; 2) position from the ellipse via the
oblique elliptical cone, eqs. (1)-(4); Shiu & Ahmad 1989, Safaee-Rad et al. 1992), batched over
N rims. Both solutions come back as a CandidateSet of circle-frame poses T_cam_circle (z axis
the normal turned towards the camera, yaw by convention) sharing one score from the fit's RMS
Sampson distance: the ellipse cannot tell them apart. The derivation: docs/design_algorithms.md,
"Circle poses". A teammate's base seen as an ellipse in ideal pixels -> its two candidate poses
target_T_sensor with their covariance (centre from the ellipse's accuracy, the normal's tilt
`normal_sigma`, the unobservable yaw `yaw_sigma`): `circle_candidates`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Sequence

import gtsam
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from graphloc.cameras import PinholeCamera, check_rows, normalize_rows
from graphloc.candidates import CandidateSet
from graphloc.vision.ellipse import FITTERS, ellipse_to_conic, fit_ellipse, sampson_rms

STATUS_OK = "ok"
STATUS_TOO_FEW = "too_few_points"  # fewer than min_points finite rim points
STATUS_EDGE_ON = "edge_on"  # collinear rim or ellipse axis ratio < min_axis_ratio
STATUS_FIT_FAILED = "fit_failed"  # OpenCV returned a non-finite or empty ellipse
STATUS_NO_CONE = "no_real_cone"  # the ellipse does not back-project to a real elliptic cone

FITS = tuple(sorted(FITTERS))  # the ellipse fits CircleConfig.fit names


@config_dataclass
class CircleConfig:
    """min_points: rim points needed after dropping non-finite ones (OpenCV needs >= 5).
    min_axis_ratio: minor/major axis of the fitted ellipse below which the circle counts as
    seen edge-on (no usable normal). pixel_sigma: rim noise [px] used in the score.
    fit: 'direct' (cv2.fitEllipseDirect), 'ams' (cv2.fitEllipseAMS) or 'lsq' (cv2.fitEllipse)."""

    min_points: int = setting(6, ge=5)
    min_axis_ratio: float = setting(0.05, gt=0.0, lt=1.0)
    pixel_sigma: float = setting(1.0, gt=0.0)
    fit: Literal[FITS] = "direct"


@dataclass(frozen=True)
class CirclePoses:
    """Result for N rims. centres, normals: (N,2,3) in the camera frame, NaN where status[n]
    is not 'ok'; ellipses: (N,5) fitted ellipse in ideal (undistorted) pixels as
    (u0, v0, full width, full height, angle deg) in OpenCV's RotatedRect convention;
    rms_px (N,): RMS Sampson distance of the rim to the ellipse; n_points (N,) used,
    n_skipped (N,) non-finite rim rows dropped; status (N,): one of the STATUS_* codes
    ('ok', 'too_few_points', 'edge_on', 'fit_failed', 'no_real_cone'); explain(n) gives the
    numbers behind it."""

    centres: np.ndarray
    normals: np.ndarray
    ellipses: np.ndarray
    rms_px: np.ndarray
    n_points: np.ndarray
    n_skipped: np.ndarray
    status: np.ndarray
    radius: float
    pixel_sigma: float

    def __len__(self) -> int:
        return len(self.status)

    @property
    def ok(self) -> np.ndarray:
        return self.status == STATUS_OK

    def explain(self, n: int) -> str:
        """One line: rim n's status with the numbers behind it."""
        w, h = self.ellipses[n, 2], self.ellipses[n, 3]
        ratio = (
            min(w, h) / max(w, h) if np.isfinite([w, h]).all() and max(w, h) > 0 else float("nan")
        )
        return (
            f"circle rim {n}: {self.status[n]} ({self.n_points[n]} finite rim points, "
            f"{self.n_skipped[n]} non-finite skipped, ellipse axis ratio {ratio:.3g})"
        )

    def candidates(
        self, n: int = 0, time: float = 0.0, observer: str = "", observed: str = ""
    ) -> CandidateSet:
        """The two poses T_cam_circle of rim n (ValueError if rim n failed)."""
        if self.status[n] != STATUS_OK:
            raise ValueError(self.explain(n))
        R = rotations_from_normals(self.normals[n])
        score = np.exp(-0.5 * (self.rms_px[n] / self.pixel_sigma) ** 2)
        return CandidateSet(
            R,
            self.centres[n],
            np.full(2, score),
            time,
            observer,
            observed,
            "circle",
            meta={
                "rms_px": float(self.rms_px[n]),
                "n_points": int(self.n_points[n]),
                "n_skipped": int(self.n_skipped[n]),
                "radius": self.radius,
            },
        )


def rotations_from_normals(normals: np.ndarray) -> np.ndarray:
    """(K,3) unit normals -> (K,3,3) rotations with z = normal, x = camera x projected on the
    plane (camera y when x is parallel to the normal); see the module docstring."""
    normals = normalize_rows(check_rows(normals, 3, "normals"))
    ref = np.tile([1.0, 0.0, 0.0], (len(normals), 1))
    ref[np.abs(normals[:, 0]) > 1.0 - 1e-6] = (0.0, 1.0, 0.0)
    x = normalize_rows(ref - np.einsum("ij,ij->i", ref, normals)[:, None] * normals)
    y = np.cross(normals, x)
    return np.stack([x, y, normals], axis=2)


def circles_from_cones(
    cones: np.ndarray, radius: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed-form circle centres and normals from (N,3,3) cones P^T Q P = 0 (camera frame,
    normalized coordinates). Returns centres (N,2,3), normals (N,2,3) (towards the camera,
    centre z > 0) and ok (N,) -- False where Q is not a real elliptic cone (signature != (2,1))."""
    Q = np.asarray(cones, dtype=float)
    lam, V = np.linalg.eigh(Q)  # ascending
    n_pos = (lam > 0).sum(axis=1)
    flip = n_pos == 1  # make two eigenvalues positive, one negative
    lam = np.where(flip[:, None], -lam[:, ::-1], lam)
    V = np.where(flip[:, None, None], V[:, :, ::-1], V)
    ok = np.isin(n_pos, (1, 2)) & np.isfinite(lam).all(axis=1)
    l3, l2, l1 = lam[:, 0], lam[:, 1], lam[:, 2]
    ok &= (l3 < 0) & (l2 > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        span = l1 - l3
        s = np.sqrt(np.maximum(l1 - l2, 0.0) / span)
        t = np.sqrt(np.maximum(l2 - l3, 0.0) / span)
        kappa = span / (2.0 * l2)
        centres, normals = [], []
        for sign in (1.0, -1.0):
            # eigen frame (axes ordered l1, l2, l3): n = (sign s, 0, t), m = (sign s, 0, -t)
            n_e = np.stack([sign * s, np.zeros_like(s), t], -1)
            m_e = np.stack([sign * s, np.zeros_like(s), -t], -1)
            nm = sign * sign * s * s - t * t
            d = radius / np.sqrt(kappa**2 - (1.0 + kappa * nm) ** 2)
            c_e = -kappa[:, None] * d[:, None] * m_e + (d * (1.0 + kappa * nm))[:, None] * n_e
            frame = V[:, :, ::-1]  # columns: eigenvectors of l1, l2, l3
            c = np.einsum("nij,nj->ni", frame, c_e)
            n = np.einsum("nij,nj->ni", frame, n_e)
            c *= np.where(c[:, 2] < 0, -1.0, 1.0)[:, None]  # d -> -d mirrors the solution
            n *= np.where(np.einsum("ni,ni->n", n, c) > 0, -1.0, 1.0)[:, None]
            centres.append(c)
            normals.append(n)
    centres, normals = np.stack(centres, 1), np.stack(normals, 1)
    ok &= np.isfinite(centres).all(axis=(1, 2)) & np.isfinite(normals).all(axis=(1, 2))
    centres[~ok] = np.nan
    normals[~ok] = np.nan
    return centres, normals, ok


def circle_poses_from_rims(
    camera: PinholeCamera,
    rims: Sequence[np.ndarray] | np.ndarray,
    radius: float,
    config: CircleConfig = CircleConfig(),
) -> CirclePoses:
    """Circle poses from N rims: rims is a sequence of (M_i,2) raw pixel arrays or an
    (N,M,2) array. Per-rim problems (too few finite points, edge-on, no real cone) are
    reported as `status` codes, never raised; wrong shapes and a bad radius are ValueErrors."""
    radius = float(radius)
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive finite number, got {radius}")
    if not isinstance(camera, PinholeCamera):
        raise ValueError(
            f"camera must be a PinholeCamera (the cone needs a perspective K), "
            f"got {type(camera).__name__}"
        )
    if isinstance(rims, np.ndarray) and rims.ndim == 3:
        rims = list(rims)
    rims = [check_rows(r, 2, f"rims[{i}]") for i, r in enumerate(rims)]
    N = len(rims)
    ellipses = np.full((N, 5), np.nan)
    rms = np.full(N, np.nan)
    status = np.full(N, STATUS_OK, dtype=object)
    # all rims undistorted in one call: ideal pixels K [x/z, y/z, 1]
    lengths = np.array([len(r) for r in rims], dtype=int)
    bearings, valid = camera.pixel_to_bearing(np.concatenate(rims) if N else np.zeros((0, 2)))
    ideal_all = bearings[:, :2] / bearings[:, 2:3] * (camera.fx, camera.fy) + (camera.cx, camera.cy)
    splits = np.cumsum(lengths)[:-1]
    valid_per_rim = np.split(valid, splits)[:N]  # [:N]: np.split of nothing still gives one piece
    ideal_rims = [ideal[v] for ideal, v in zip(np.split(ideal_all, splits), valid_per_rim)]
    n_points = np.array([v.sum() for v in valid_per_rim], dtype=int).reshape(N)
    n_skipped = lengths - n_points
    for i, ideal in enumerate(ideal_rims):
        if n_points[i] < config.min_points:
            status[i] = STATUS_TOO_FEW
            continue
        if (
            np.linalg.matrix_rank(ideal - ideal.mean(0), tol=1e-9 * max(1.0, np.abs(ideal).max()))
            < 2
        ):
            status[i] = STATUS_EDGE_ON
            continue
        ellipses[i] = fit_ellipse(ideal, config.fit)
        w, h = ellipses[i, 2], ellipses[i, 3]
        if not (np.isfinite(ellipses[i]).all() and min(w, h) > 0):
            status[i] = STATUS_FIT_FAILED
            continue
        if min(w, h) / max(w, h) < config.min_axis_ratio:
            status[i] = STATUS_EDGE_ON
    good = np.flatnonzero(status == STATUS_OK)
    conics = ellipse_to_conic(ellipses[good])
    for k, i in enumerate(good):
        rms[i] = sampson_rms(conics[k], ideal_rims[i])
    K = camera.K
    cones = np.einsum("ji,njk,kl->nil", K, conics, K)  # K^T C K
    centres = np.full((N, 2, 3), np.nan)
    normals = np.full((N, 2, 3), np.nan)
    c, n, ok = circles_from_cones(cones, radius)
    centres[good], normals[good] = c, n
    status[good[~ok]] = STATUS_NO_CONE
    return CirclePoses(
        centres,
        normals,
        ellipses,
        rms,
        n_points,
        n_skipped,
        status.astype(str),
        radius,
        config.pixel_sigma,
    )


def circle_pose_from_rim(
    camera: PinholeCamera,
    rim: np.ndarray,
    radius: float,
    config: CircleConfig = CircleConfig(),
    time: float = 0.0,
    observer: str = "",
    observed: str = "",
) -> tuple[CandidateSet, CirclePoses]:
    """One rim (M,2) of raw pixels -> (CandidateSet of the 2 poses, CirclePoses of length 1).
    ValueError (with the reason) when the rim is unusable."""
    poses = circle_poses_from_rims(camera, [check_rows(rim, 2, "rim")], radius, config)
    if not poses.ok[0]:
        raise ValueError(poses.explain(0))
    return poses.candidates(0, time, observer, observed), poses


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
