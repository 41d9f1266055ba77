"""Planar (Pose2) range-bearing factors and pose helpers: graphloc builds every graph in Pose3,
so these serve only the tests and benchmarks that build a planar graph by hand (GTSAM's
BearingRangeFactor2D / BearingRangeFactorPose2; the BearingRange factors have no sensor offset,
so a mounted sensor's measurements are first re-expressed in the body frame)."""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.factors.range_bearing import check_measurement, measurement_noise
from graphloc.factors.robust import Kernel


def landmark_factor_2d(
    pose_key: int,
    landmark_key: int,
    bearing: float,
    range_: float,
    sigmas=(0.05, 0.1),
    kernel: Kernel = Kernel(),
) -> gtsam.BearingRangeFactor2D:
    """Planar robot at `pose_key` sees landmark point `landmark_key` at (bearing, range)."""
    check_measurement(bearing, range_)
    return gtsam.BearingRangeFactor2D(
        pose_key,
        landmark_key,
        gtsam.Rot2(float(bearing)),
        float(range_),
        measurement_noise(sigmas, 2, kernel),
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
    check_measurement(bearing, range_)
    return gtsam.BearingRangeFactorPose2(
        observer_key,
        observed_key,
        gtsam.Rot2(float(bearing)),
        float(range_),
        measurement_noise(sigmas, 2, kernel),
    )


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


def compose_poses(poses: np.ndarray, deltas: np.ndarray) -> np.ndarray:
    """(N,3) planar poses composed with (N,3) relative poses, row by row (vectorized)."""
    p, d = np.asarray(poses, dtype=float), np.asarray(deltas, dtype=float)
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    return np.stack(
        [
            p[:, 0] + c * d[:, 0] - s * d[:, 1],
            p[:, 1] + s * d[:, 0] + c * d[:, 1],
            (p[:, 2] + d[:, 2] + np.pi) % (2 * np.pi) - np.pi,
        ],
        axis=1,
    )
