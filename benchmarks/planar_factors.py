"""Planar (Pose2) range-bearing factors and pose helpers: graphloc builds every graph in Pose3,
so these serve only the tests and benchmarks that build a planar graph by hand (GTSAM's
BearingRangeFactor2D / BearingRangeFactorPose2; the BearingRange factors have no sensor offset,
so a mounted sensor's measurements are first re-expressed in the body frame), and the whole-run
unicycle integrator `integrate_unicycle` that `graphloc.live.arc.ArcIntegrator` carries forward
row by row (the tests' reference)."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from graphloc.factors.odometry import VelocityNoise, _wrap, relative_poses, step_covariances
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


@dataclass(frozen=True)
class UnicycleIntegration:
    """poses: (K,3) dead-reckoned (x, y, theta) at the keyframe times, starting at `start`;
    deltas: (K-1,3) relative poses keyframe k -> k+1 in frame k; covariances: (K-1,3,3)."""

    poses: np.ndarray
    deltas: np.ndarray
    covariances: np.ndarray


def integrate_unicycle(
    times: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
    keyframe_times: np.ndarray,
    noise: VelocityNoise = VelocityNoise(),
    start=(0.0, 0.0, 0.0),
) -> UnicycleIntegration:
    """Integrate velocity samples (zero-order hold: sample i holds from times[i] to times[i+1];
    before times[0] the robot stands still, the last sample holds to the end) exactly along arcs,
    to poses at `keyframe_times`, with first-order propagated covariance of each keyframe step.

    Vectorized: headings are a cumulative sum, positions a cumulative sum of rotated arc chords,
    covariances a segment-wise sum (np.add.reduceat) of G Q G^T with G the 3x2 Jacobian of the
    end pose w.r.t. each segment's (distance, heading) increments.
    """
    times, v, w = (np.asarray(a, dtype=float) for a in (times, v, w))
    kf = np.asarray(keyframe_times, dtype=float)
    if times.ndim != 1 or v.shape != times.shape or w.shape != times.shape:
        raise ValueError(
            "integrate_unicycle: times, v, w must be equal-length 1-D arrays, "
            f"got {times.shape}, {v.shape}, {w.shape}"
        )
    if kf.ndim != 1 or kf.size < 1:
        raise ValueError("integrate_unicycle: need at least one keyframe time")
    for name, arr in (("times", times), ("v", v), ("w", w), ("keyframe_times", kf)):
        if not np.isfinite(arr).all():
            raise ValueError(f"integrate_unicycle: {name} contains NaN/inf")
    if np.any(np.diff(times) < 0) or np.any(np.diff(kf) <= 0):
        raise ValueError(
            "integrate_unicycle: times must be non-decreasing and keyframe_times increasing"
        )

    # breakpoints: keyframes plus every sample time strictly inside the keyframe span
    inside = times[(times > kf[0]) & (times < kf[-1])]
    bp = np.union1d(kf, inside)
    dt = np.diff(bp)
    sample = np.searchsorted(times, bp[:-1], side="right") - 1  # sample active on each segment
    active = sample >= 0
    seg_v = np.where(active, v[np.maximum(sample, 0)], 0.0)
    seg_w = np.where(active, w[np.maximum(sample, 0)], 0.0)
    ds = seg_v * dt
    dth = seg_w * dt
    # exact arc chord in the segment's start frame
    half = 0.5 * dth
    sinc_half = np.sinc(half / np.pi)  # sin(h)/h
    chord = ds * sinc_half
    theta = start[2] + np.concatenate([[0.0], np.cumsum(dth)])
    mid = theta[:-1] + half
    x = start[0] + np.concatenate([[0.0], np.cumsum(chord * np.cos(mid))])
    y = start[1] + np.concatenate([[0.0], np.cumsum(chord * np.sin(mid))])

    kf_idx = np.searchsorted(bp, kf)
    poses = np.stack([x[kf_idx], y[kf_idx], _wrap(theta[kf_idx])], axis=1)
    deltas = relative_poses(np.stack([x[kf_idx], y[kf_idx], theta[kf_idx]], axis=1))

    # covariance: each segment j in keyframe interval k perturbs the end pose e=k+1 by
    # G_j [d_s, d_theta]^T with G_j = [[cos th_j, -(y_e - y_j)], [sin th_j, x_e - x_j], [0, 1]]
    if kf.size == 1:
        return UnicycleIntegration(poses, deltas, np.zeros((0, 3, 3)))
    return UnicycleIntegration(poses, deltas, step_covariances(x, y, theta, mid, dt, kf_idx, noise))
