"""Odometry and scan-matching between-factors (gtsam.BetweenFactorPose2 / BetweenFactorPose3)
with the covariance of the odometry model or the scan matcher, and unicycle velocity odometry
(v, omega) integrated to keyframes with its covariance propagated analytically (seed 004
sec. II.3, Algorithm 1, samples the same motion noise in a particle filter). Covariances in
GTSAM's tangent order.
"""

from __future__ import annotations


import gtsam
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from graphloc.factors.mixture import check_covariances
from graphloc.factors.robust import Kernel, robust_noise


def between_factor(
    key_a: int, key_b: int, relative, covariance: np.ndarray, kernel: Kernel = Kernel()
):
    """Between-factor of relative pose `relative` (gtsam.Pose2/Pose3, or a 3x3 / 4x4 homogeneous
    matrix, e.g. from ICP) with `covariance` (3x3 or 6x6) from the odometry model or matcher."""
    if isinstance(relative, np.ndarray):
        relative = _pose_from_matrix(relative)
    cov = np.asarray(covariance, dtype=float)
    dim = 3 if isinstance(relative, gtsam.Pose2) else 6
    if not isinstance(relative, (gtsam.Pose2, gtsam.Pose3)):
        raise ValueError(
            "between_factor: relative must be Pose2/Pose3 or a 3x3/4x4 matrix, "
            f"got {type(relative)}"
        )
    if cov.shape != (dim, dim):
        raise ValueError(
            f"between_factor: covariance must be {dim}x{dim} for {type(relative).__name__}, "
            f"got {cov.shape}"
        )
    check_covariance(cov, "between_factor covariance")
    noise = robust_noise(gtsam.noiseModel.Gaussian.Covariance(cov), kernel)
    if dim == 3:
        return gtsam.BetweenFactorPose2(key_a, key_b, relative, noise)
    return gtsam.BetweenFactorPose3(key_a, key_b, relative, noise)


def check_covariance(cov: np.ndarray, what: str) -> None:
    """ValueError unless `cov` is finite, symmetric and positive definite (one matrix of
    `factors.mixture.check_covariances`)."""
    check_covariances(np.asarray(cov, dtype=float)[None], what)


def _pose_from_matrix(T: np.ndarray):
    if T.shape == (3, 3):
        return gtsam.Pose2(float(T[0, 2]), float(T[1, 2]), float(np.arctan2(T[1, 0], T[0, 0])))
    if T.shape == (4, 4):
        return gtsam.Pose3(T)
    raise ValueError(f"relative pose matrix must be 3x3 or 4x4, got {T.shape}")


# ---- unicycle velocity odometry --------------------------------------------------------------
@config_dataclass
class VelocityNoise:
    """Velocity noise model of a unicycle: white noise densities on forward speed
    (density_v [m/sqrt(s)]) and turn rate (density_w [rad/sqrt(s)]), plus a per-keyframe floor
    (floor_xy [m], floor_theta [rad]) so that a standing robot still has a proper covariance."""

    density_v: float = setting(0.05, gt=0.0)
    density_w: float = setting(0.08, gt=0.0)
    floor_xy: float = setting(0.002, gt=0.0)
    floor_theta: float = setting(0.002, gt=0.0)


def step_covariances(x, y, theta, mid, dt, kf_idx, noise) -> np.ndarray:
    """The first-order covariance of each keyframe step of an integrated unicycle path (the
    breakpoints' x, y, theta, each segment's mid heading and length dt, the keyframes'
    breakpoint indices kf_idx): a segment-wise sum (np.add.reduceat) of G Q G^T with G the 3x2
    Jacobian of the step's end pose w.r.t. each segment's (distance, heading) increments,
    expressed in the end pose's frame, plus the noise floors; symmetrized."""
    seg_interval = np.searchsorted(kf_idx, np.arange(dt.size), side="right") - 1
    end = kf_idx[seg_interval + 1]
    ex, ey = x[end] - x[:-1], y[end] - y[:-1]
    var_s = noise.density_v**2 * dt
    var_t = noise.density_w**2 * dt
    c, s = np.cos(mid), np.sin(mid)
    g = np.zeros((dt.size, 3, 2))
    g[:, 0, 0], g[:, 1, 0] = c, s
    g[:, 0, 1], g[:, 1, 1], g[:, 2, 1] = -ey, ex, 1.0
    contrib = (
        var_s[:, None, None] * g[:, :, 0, None] * g[:, None, :, 0]
        + var_t[:, None, None] * g[:, :, 1, None] * g[:, None, :, 1]
    )
    cov_world = np.add.reduceat(contrib, kf_idx[:-1], axis=0)
    # express in the frame of the end pose (GTSAM Pose2 tangent of BetweenFactor error)
    th_end = theta[kf_idx[1:]]
    rot = np.zeros((th_end.size, 3, 3))
    ce, se = np.cos(th_end), np.sin(th_end)
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = ce, se, -se, ce, 1.0
    cov = rot @ cov_world @ np.transpose(rot, (0, 2, 1))
    cov += np.diag([noise.floor_xy**2, noise.floor_xy**2, noise.floor_theta**2])
    return 0.5 * (cov + np.transpose(cov, (0, 2, 1)))


def relative_poses(poses: np.ndarray) -> np.ndarray:
    """(K,3) planar poses -> (K-1,3) relative poses pose_k^-1 * pose_{k+1} (vectorized)."""
    p = np.asarray(poses, dtype=float)
    return between_poses(p[:-1], p[1:])


def between_poses(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a_i^-1 * b_i for planar poses (N,3) (vectorized)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    return np.stack([c * dx + s * dy, -s * dx + c * dy, _wrap(b[:, 2] - a[:, 2])], axis=1)


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi
