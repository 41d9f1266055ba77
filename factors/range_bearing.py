"""3D range-bearing factors to landmarks and between robots on GTSAM's built-ins
(BearingRangeFactor3D, BearingRangeFactorPose3, KnownLandmarkFactorPose3); noise sigmas
(bearing 2 DOF [rad], range [m])."""

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


def measurement_noise(sigmas, dim: int, kernel: Kernel):
    return robust_noise(gtsam.noiseModel.Diagonal.Sigmas(_sigmas(sigmas, dim)), kernel)


def check_measurement(bearing, range_):
    if not (np.isfinite(bearing).all() and np.isfinite(range_).all()):
        raise ValueError("range-bearing measurement contains NaN/inf")
    if np.any(np.asarray(range_) <= 0):
        raise ValueError("range-bearing measurement has a non-positive range")


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
    check_measurement(d, range_)
    return gtsam.BearingRangeFactor3D(
        pose_key, landmark_key, gtsam.Unit3(d), float(range_), measurement_noise(sigmas, 3, kernel)
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
    check_measurement(d, range_)
    return gtsam.BearingRangeFactorPose3(
        observer_key,
        observed_key,
        gtsam.Unit3(d),
        float(range_),
        measurement_noise(sigmas, 3, kernel),
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
    check_measurement(d, range_)
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
