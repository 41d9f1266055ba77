"""Range-bearing factors to landmarks and between robots, on GTSAM's built-ins:

2D: gtsam.BearingRangeFactor2D (Pose2 -> Point2 landmark), gtsam.BearingRangeFactorPose2
    (Pose2 -> position of another robot's Pose2);
3D: gtsam.BearingRangeFactor3D (Pose3 -> Point3, bearing as Unit3), gtsam.BearingRangeFactorPose3.

Robots observing each other (seed 000, 000_05137a0a9c449be3.txt sec. III: ground robots with
mutual visibility) are the inter-robot factors; MRCLAM supplies range + bearing for both kinds.

Measurements taken by a sensor mounted at `body_P_sensor` are first re-expressed in the body
frame (`to_body_frame_2d`) because the Python BearingRange factors have no sensor offset.
Noise: sigmas (bearing [rad], range [m]) in 2D, (bearing 2 DOF [rad], range [m]) in 3D.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np

from graphloc.factors.robust import Kernel, robust_noise


def _sigmas(sigmas, dim: int) -> np.ndarray:
    sig = np.asarray(sigmas, dtype=float)
    if sig.shape != (dim,) or not np.isfinite(sig).all() or np.any(sig <= 0):
        raise ValueError(
            f"range-bearing sigmas must be {dim} finite positive numbers, got {sigmas}"
        )
    return sig


def _noise(sigmas, dim: int, kernel: Kernel):
    return robust_noise(gtsam.noiseModel.Diagonal.Sigmas(_sigmas(sigmas, dim)), kernel)


def _check(bearing, range_):
    if not (np.isfinite(bearing).all() and np.isfinite(range_).all()):
        raise ValueError("range-bearing measurement contains NaN/inf")
    if np.any(np.asarray(range_) <= 0):
        raise ValueError("range-bearing measurement has a non-positive range")


def landmark_factor_2d(
    pose_key: int,
    landmark_key: int,
    bearing: float,
    range_: float,
    sigmas=(0.05, 0.1),
    kernel: Kernel = Kernel(),
) -> gtsam.BearingRangeFactor2D:
    """Planar robot at `pose_key` sees landmark point `landmark_key` at (bearing, range)."""
    _check(bearing, range_)
    return gtsam.BearingRangeFactor2D(
        pose_key, landmark_key, gtsam.Rot2(float(bearing)), float(range_), _noise(sigmas, 2, kernel)
    )


def robot_factor_2d(
    observer_key: int,
    observed_key: int,
    bearing: float,
    range_: float,
    sigmas=(0.05, 0.1),
    kernel: Kernel = Kernel(),
) -> gtsam.BearingRangeFactorPose2:
    """Planar robot at `observer_key` sees the origin of robot pose `observed_key` at
    (bearing, range)."""
    _check(bearing, range_)
    return gtsam.BearingRangeFactorPose2(
        observer_key,
        observed_key,
        gtsam.Rot2(float(bearing)),
        float(range_),
        _noise(sigmas, 2, kernel),
    )


def landmark_factor_3d(
    pose_key: int,
    landmark_key: int,
    direction,
    range_: float,
    sigmas=(0.05, 0.05, 0.1),
    kernel: Kernel = Kernel(),
) -> gtsam.BearingRangeFactor3D:
    """Robot pose (Pose3) sees landmark point (Point3) along unit `direction` (body frame) at
    `range_`."""
    d = _unit(direction)
    _check(d, range_)
    return gtsam.BearingRangeFactor3D(
        pose_key, landmark_key, gtsam.Unit3(d), float(range_), _noise(sigmas, 3, kernel)
    )


def robot_factor_3d(
    observer_key: int,
    observed_key: int,
    direction,
    range_: float,
    sigmas=(0.05, 0.05, 0.1),
    kernel: Kernel = Kernel(),
) -> gtsam.BearingRangeFactorPose3:
    """Robot pose (Pose3) sees the origin of another robot's Pose3 along `direction` at `range_`."""
    d = _unit(direction)
    _check(d, range_)
    return gtsam.BearingRangeFactorPose3(
        observer_key, observed_key, gtsam.Unit3(d), float(range_), _noise(sigmas, 3, kernel)
    )


def known_landmark_factor_3d(
    pose_key: int,
    landmark_xyz,
    landmark_sigma: float,
    direction,
    range_: float,
    sigmas=(0.05, 0.05, 0.1),
    kernel: Kernel = Kernel(),
) -> gtsam.KnownLandmarkFactorPose3:
    """Robot pose (Pose3) sees a landmark of known position `landmark_xyz` (isotropic std
    `landmark_sigma` [m]) along `direction` at `range_`, with no landmark variable: GTSAM's
    KnownLandmarkFactorPose3 (residual pose.transformTo(landmark) - direction * range, body
    frame). Its covariance is the range-bearing noise carried to the point, r^2 sb^2 (I - d d^T)
    + sr^2 d d^T, plus the landmark's sigma^2 I (rotation invariant): the landmark variable with
    its prior and landmark_factor_3d, marginalized at the measured point."""
    d = _unit(direction)
    _check(d, range_)
    if not (np.isfinite(landmark_sigma) and landmark_sigma >= 0):
        raise ValueError(f"landmark sigma must be finite >= 0, got {landmark_sigma}")
    sb, _, sr = _sigmas(sigmas, 3).tolist()
    across = range_**2 * sb**2  # r^2 sb^2 (I - d d^T) + sr^2 d d^T + sigma^2 I
    cov = (sr**2 - across) * (d[:, None] * d)
    cov.flat[::4] += across + float(landmark_sigma) ** 2
    noise = robust_noise(gtsam.noiseModel.Gaussian.Covariance(cov), kernel)
    return gtsam.KnownLandmarkFactorPose3(
        pose_key, np.asarray(landmark_xyz, dtype=float), d * float(range_), noise
    )


def _unit(direction) -> np.ndarray:
    d = np.asarray(direction, dtype=float).reshape(-1)
    n = math.sqrt(d @ d) if d.shape == (3,) else 0.0
    if not math.isfinite(n) or n < 1e-12:
        raise ValueError(f"bearing direction must be a finite non-zero 3-vector, got {direction}")
    return d / n


def to_body_frame_2d(bearing: np.ndarray, range_: np.ndarray, body_P_sensor=(0.0, 0.0, 0.0)):
    """Re-express (bearing, range) measured in a sensor frame mounted at
    body_P_sensor = (x, y, theta) as (bearing, range) from the body origin (vectorized over
    arrays)."""
    b, r = np.asarray(bearing, dtype=float), np.asarray(range_, dtype=float)
    sx, sy, st = (float(a) for a in body_P_sensor)
    if sx == 0.0 and sy == 0.0 and st == 0.0:
        return b, r
    px = sx + r * np.cos(b + st)
    py = sy + r * np.sin(b + st)
    return np.arctan2(py, px), np.hypot(px, py)


def bearing_range_2d(poses: np.ndarray, points: np.ndarray):
    """Predicted (bearing, range) from planar poses (N,3) to points (N,2), vectorized."""
    p, q = np.asarray(poses, dtype=float), np.asarray(points, dtype=float)
    dx, dy = q[:, 0] - p[:, 0], q[:, 1] - p[:, 1]
    bearing = (np.arctan2(dy, dx) - p[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return bearing, np.hypot(dx, dy)
