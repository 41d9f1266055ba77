"""The geometry of one branching of `graphloc.hypotheses.pose_graph`: factors of a measurement's
candidates, the rigid move of a trajectory's tail when a bridge edge changes candidate, the
predicted chi-square of new factors under each combination of candidates, and a fresh iSAM2
from a factor list (the one way a hypothesis is copied: GTSAM's ISAM2 cannot be cloned).

A bridge edge (a -> b) is an edge whose removal disconnects the graph: every pose after b in
insertion order hangs on it alone. Switching its candidate from z to z' leaves the error of
every other factor unchanged if the tail moves rigidly by G = T_a z' T_b^-1 (T_b the current
estimate of b, about T_a z), so the switched hypothesis starts at its own optimum; loop
closures arriving later tell the candidates apart (Olson's loop consistency; MH-iSAM2's
hypothesis tree, Hsiao & Kaess, ICRA 2019, keeps such branches in one Bayes tree; here one
iSAM2 per branch)."""

from __future__ import annotations

import itertools

import gtsam
import numpy as np


def pose_of(values: np.ndarray, dim: int):
    """Pose2 from (x, y, theta) or Pose3 from (x, y, z, qx, qy, qz, qw)."""
    if dim == 2:
        return gtsam.Pose2(*map(float, values))
    x, y, z, qx, qy, qz, qw = map(float, values)
    return gtsam.Pose3(gtsam.Rot3.Quaternion(qw, qx, qy, qz), gtsam.Point3(x, y, z))


def noise_of(information, sigmas, dim: int):
    """A Gaussian noise model from an information matrix, else diagonal `sigmas`."""
    if information is not None:
        return gtsam.noiseModel.Gaussian.Information(np.asarray(information, float))
    return gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, float))


def between(dim: int, key_a: int, key_b: int, pose, noise):
    cls = gtsam.BetweenFactorPose2 if dim == 2 else gtsam.BetweenFactorPose3
    return cls(key_a, key_b, pose, noise)


def prior(dim: int, key: int, pose, noise):
    cls = gtsam.PriorFactorPose2 if dim == 2 else gtsam.PriorFactorPose3
    return cls(key, pose, noise)


def estimate_of(isam: gtsam.ISAM2, key: int, dim: int):
    return isam.calculateEstimatePose2(key) if dim == 2 else isam.calculateEstimatePose3(key)


def insert(values: gtsam.Values, key: int, pose) -> None:
    values.insert(key, pose)


def tail_moves(bridges, choices: dict, poses) -> list:
    """[(position, G)] in position order: the rigid moves of the tails behind the bridges whose
    choice changes. `bridges`: [(position of a, key a, position of b, key b, candidate poses,
    current index)] in position order, `choices`: bridge index in that list -> new index,
    `poses`: key -> current pose (read for a and b only). The moves compose: the tail behind a
    later bridge moves with the earlier ones."""
    moves = []
    for i, (pos_a, key_a, pos_b, key_b, candidates, current) in enumerate(bridges):
        new = choices.get(i, current)
        if new == current:
            continue
        t_a, t_b = moved(poses[key_a], pos_a, moves), moved(poses[key_b], pos_b, moves)
        moves.append((pos_b, t_a.compose(candidates[new]).compose(t_b.inverse())))
    return moves


def moved(pose, position: int, moves: list):
    """`pose` (at `position`) after the rigid moves of every tail it belongs to."""
    for start, g in moves:
        if position >= start:
            pose = g.compose(pose)
    return pose


def predicted_chi2(factors, keys_positions: dict, poses: dict, moves: list) -> float:
    """Twice the error (chi-square) of `factors` at the current poses moved by `moves`."""
    values = gtsam.Values()
    for key, position in keys_positions.items():
        values.insert(key, moved(poses[key], position, moves))
    return float(sum(2.0 * f.error(values) for f in factors))


def combinations(sizes: list[int], limit: int):
    """Every combination of indices for choices with `sizes` options, at most `limit` of
    them (itertools.product order)."""
    return list(itertools.islice(itertools.product(*[range(n) for n in sizes]), limit))


def fresh_isam(params: gtsam.ISAM2Params, graph: gtsam.NonlinearFactorGraph, values):
    """An iSAM2 holding `graph` linearized at `values` (one batch elimination)."""
    isam = gtsam.ISAM2(params)
    isam.update(graph, values)
    return isam


def moved_values(estimate: gtsam.Values, order: list[int], moves: list, dim: int) -> gtsam.Values:
    """`estimate` with every pose behind a switched bridge moved rigidly (`order`: keys by
    insertion position)."""
    if not moves:
        return estimate
    first = moves[0][0]
    out = gtsam.Values(estimate)
    get = out.atPose2 if dim == 2 else out.atPose3
    for position in range(first, len(order)):
        key = order[position]
        if out.exists(key):  # not the poses the current step introduces
            out.update(key, moved(get(key), position, moves))
    return out
