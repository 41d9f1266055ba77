"""Seed 000 (000_05137a0a9c449be3.txt) Sec. VI-A, graphloc's estimate of one deterministic
trial: one GTSAM graph over all six cameras (three ground robots, three snapshots of the
climbing robot's camera), started from the P3P rotations that best explain all nine bearings
of the ground robots (`shared_rotation_initials`). The seed's own answer (P3P per snapshot +
the straight-line test, Sec. IV) is `graphloc.baselines.straight_line`; the Table I trials
that run both are in `graphloc.experiments.seed000`.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from graphloc.baselines.straight_line import bearings_from_pixels
from graphloc.cameras import PinholeCamera, angular_sigma
from graphloc.factors.bearing import bearing_factor, known_baseline_factor
from graphloc.geometry.so3 import skew
from graphloc.keys import pose_key


@dataclass(frozen=True)
class Formation:
    """Inputs of one Table I trial for graphloc's joint estimate. ground_R (3,3,3), ground_t
    (3,3): initial ground-camera poses (C1 exact, C2, C3 from graphloc.vision.mutual);
    mutual (3,3,3): omni bearings mutual[i, j] of robot j in camera i, mutual_sigma (3,3) [rad];
    baseline: |T_12|; climber (3,3,3): bearings of the ground robots in the climbing camera
    [snapshot, robot], climber_sigma (3,3) [rad]."""

    ground_R: np.ndarray
    ground_t: np.ndarray
    mutual: np.ndarray
    mutual_sigma: np.ndarray
    baseline: float
    climber: np.ndarray
    climber_sigma: np.ndarray


def formations(trials, triangle, pixel_sigma: float) -> list[Formation | None]:
    """One Formation per trial. trials: the climbing camera's snapshots (ground (T,3,3),
    pixels (T,3,3,2), K (3,3); `graphloc.datasets.feng_deterministic.StraightLineTrials`);
    triangle: the ground robots' mutual front-end (estimated, R_estimated, bearings,
    bearing_sigma; `feng_deterministic.GroundTriangle`); pixel_sigma [px] the seed's image
    noise. Rows whose ground triangle was rejected: None."""
    K = trials.K
    pinhole = PinholeCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], 640, 480)
    climber = bearings_from_pixels(trials.pixels, K)
    climber_sigma = angular_sigma(pinhole, trials.pixels, pixel_sigma)
    out: list[Formation | None] = []
    for i in range(len(trials.ground)):
        if not np.isfinite(triangle.estimated[i]).all():
            out.append(None)
            continue
        baseline = float(np.linalg.norm(trials.ground[i, 1] - trials.ground[i, 0]))
        out.append(
            Formation(
                triangle.R_estimated[i],
                triangle.estimated[i],
                triangle.bearings[i],
                triangle.bearing_sigma[i],
                baseline,
                climber[i],
                climber_sigma[i],
            )
        )
    return out


def shared_rotation_initials(
    pixels: np.ndarray,
    K: np.ndarray,
    ground: np.ndarray,
    R_cand: np.ndarray,
    valid: np.ndarray,
    keep: int = 2,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Initial values for the joint estimate (vectorized over trials and candidate rotations).
    pixels (T,3,3,2) [trial, snapshot, robot]; ground (T,3,3); R_cand (T,M,3,3) candidate
    camera rotations from P3P of any snapshot, valid (T,M). With the rotation fixed, each
    snapshot's camera centre is linear in the bearings ([f]_x R^T (X - c) = 0, least squares).
    Returns the `keep` best rotations (T,keep,3,3), centres (T,keep,3,3) and their mean squared
    angular residuals (T,keep) [rad^2] over the 9 bearings (inf: fewer valid candidates)."""
    f = bearings_from_pixels(pixels, K)  # (T,3,3,3) [trial, snapshot, robot, xyz]
    fx = skew(f)
    Rt = np.swapaxes(R_cand, -1, -2)  # (T,M,3,3)
    A = np.einsum("tsjab,tmbc->tmsjac", fx, Rt)  # (T,M,S,J,3,3)
    b = np.einsum("tmsjab,tjb->tmsja", A, ground)
    AtA = np.einsum("tmsjba,tmsjbc->tmsac", A, A)
    Atb = np.einsum("tmsjba,tmsjb->tmsa", A, b)
    with np.errstate(all="ignore"):
        c = np.linalg.solve(AtA + 1e-12 * np.eye(3), Atb[..., None])[..., 0]  # (T,M,S,3)
        pc = np.einsum("tmab,tmsjb->tmsja", Rt, ground[:, None, None, :, :] - c[:, :, :, None, :])
        cos = np.einsum("tmsja,tsja->tmsj", pc, f) / np.linalg.norm(pc, axis=-1)
    residual = np.mean(np.arccos(np.clip(cos, -1.0, 1.0)) ** 2, axis=(2, 3))
    residual = np.where(valid & np.isfinite(residual), residual, np.inf)
    best = np.argsort(residual, axis=1)[:, :keep]
    idx = np.arange(len(best))[:, None]
    return R_cand[idx, best], c[idx, best], residual[idx, best]


def joint_estimate(
    f: Formation,
    R0: np.ndarray,
    c0: np.ndarray,
    rotation_sigma: float = 1e-4,
    reference_sigma: float = 1e-6,
) -> tuple[np.ndarray, np.ndarray, float]:
    """graphloc's estimate of one trial, one GTSAM graph over all six cameras (keys: ground
    robot j = pose_key(j + 1, 0), climbing-camera snapshot s = pose_key(0, s)):
    - C1: PriorFactorPose3 (the reference, seed 000 Sec. VI-A Table I "C1 (Ref)");
    - the 6 mutual omni bearings and the 9 bearings of the ground robots in the climbing
      camera: graphloc.factors.bearing.bearing_factor (Pose3 -> Pose3);
    - |T_12|: known_baseline_factor (seed 000 Problem 1 fixes the scale);
    - BetweenFactorPose3 between consecutive snapshots holding the rotation (the robot drives
      straight without turning), translation free.
    So the climbing camera's views also refine C2, C3 (the seed solves them separately).
    Levenberg-Marquardt from the mutual triangle and (R0, c0). Returns the snapshot centres
    (3,3), the ground positions (3,3) and the final graph error (NaN, NaN, inf if GTSAM
    fails, e.g. an indeterminant system)."""
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for j in range(3):
        values.insert(pose_key(j + 1, 0), gtsam.Pose3(gtsam.Rot3(f.ground_R[j]), f.ground_t[j]))
        for i in range(3):
            if i != j:
                graph.add(
                    bearing_factor(
                        pose_key(i + 1, 0), pose_key(j + 1, 0), f.mutual[i, j], f.mutual_sigma[i, j]
                    )
                )
    reference = gtsam.Pose3(gtsam.Rot3(f.ground_R[0]), f.ground_t[0])
    graph.add(
        gtsam.PriorFactorPose3(
            pose_key(1, 0), reference, gtsam.noiseModel.Isotropic.Sigma(6, reference_sigma)
        )
    )
    graph.add(known_baseline_factor(pose_key(1, 0), pose_key(2, 0), f.baseline, reference_sigma))
    hold = gtsam.noiseModel.Diagonal.Sigmas(np.array([rotation_sigma] * 3 + [1e3] * 3))
    for s in range(3):
        values.insert(pose_key(0, s), gtsam.Pose3(gtsam.Rot3(R0), c0[s]))
        for j in range(3):
            graph.add(
                bearing_factor(
                    pose_key(0, s), pose_key(j + 1, 0), f.climber[s, j], f.climber_sigma[s, j]
                )
            )
        if s:
            graph.add(
                gtsam.BetweenFactorPose3(pose_key(0, s - 1), pose_key(0, s), gtsam.Pose3(), hold)
            )
    params = gtsam.LevenbergMarquardtParams()
    try:
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    except RuntimeError:  # e.g. an indeterminant system from a degenerate start: a failed trial
        return np.full((3, 3), np.nan), np.full((3, 3), np.nan), np.inf
    return (
        np.stack([result.atPose3(pose_key(0, s)).translation() for s in range(3)]),
        np.stack([result.atPose3(pose_key(j + 1, 0)).translation() for j in range(3)]),
        graph.error(result),
    )


def best_joint(f: Formation, R0s, c0s, residuals) -> tuple[np.ndarray, np.ndarray, float]:
    """joint_estimate from each initial rotation (finite residual); the lowest graph error
    wins (NaN, NaN, inf without any)."""
    runs = [joint_estimate(f, R0, c0) for R0, c0, r in zip(R0s, c0s, residuals) if np.isfinite(r)]
    if not runs:
        return np.full((3, 3), np.nan), np.full((3, 3), np.nan), np.inf
    return min(runs, key=lambda run: run[2])
