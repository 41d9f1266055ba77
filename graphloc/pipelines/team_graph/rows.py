"""Estimates as rows: x y z qx qy qz qw per pose, per robot (`TeamResult.estimate`, `causal`,
`dead_reckoning`), in one vectorized pass rather than a GTSAM round trip per pose."""

from __future__ import annotations

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.keys import decode_many


def pose_row(p: gtsam.Pose3) -> np.ndarray:
    """(7,) x y z qx qy qz qw of one pose."""
    return rows_of_matrices(p.matrix()[None])[0]


def rows_of_matrices(m: np.ndarray) -> np.ndarray:
    """(N,7) x y z qx qy qz qw of (N,4,4) or (N,3,4) poses (one vectorized pass; a pose at a
    time costs a GTSAM round trip each). The quaternion's sign is GTSAM's (`Rot3.toQuaternion`,
    Eigen's conversion): w > 0 where the trace is positive, else the component of the largest
    diagonal entry."""
    if not len(m):
        return np.zeros((0, 7))
    r = m[:, :3, :3]
    q = Rotation.from_matrix(r).as_quat()  # x y z w
    ref = np.where(
        np.trace(r, axis1=1, axis2=2) > 0, 3, np.argmax(np.diagonal(r, axis1=1, axis2=2), axis=1)
    )
    q *= np.where(q[np.arange(len(q)), ref] < 0, -1.0, 1.0)[:, None]
    return np.hstack([m[:, :3, 3], q])


def grid_rows(grid: np.ndarray) -> np.ndarray:
    """(K,7) rows of (K,3,4) pose matrices [R | t], NaN rows where the grid is NaN."""
    rows = np.full((len(grid), 7), np.nan)
    ok = np.isfinite(grid[:, 0, 0])
    rows[ok] = rows_of_matrices(grid[ok])
    return rows


def trajectory_rows(node_times: list, poses: dict) -> list:
    """Per robot, (K_r,7) rows of `poses` ((robot, index) -> (4,4) matrix), NaN where absent."""
    out = [np.full((len(times), 7), np.nan) for times in node_times]
    if poses:
        where = np.array(list(poses), dtype=int).reshape(-1, 2)
        rows = rows_of_matrices(np.array(list(poses.values())))
        for r, rows_r in enumerate(out):
            mine = where[:, 0] == r
            rows_r[where[mine, 1]] = rows[mine]
    return out


def estimate_matrices(values: gtsam.Values) -> dict:
    """(robot, index) -> (4,4) of every pose in `values` (one `extractPose3` call)."""
    poses = gtsam.utilities.allPose3s(values)
    kind, robot, k = decode_many(poses.keys())
    flat = gtsam.utilities.extractPose3(poses).reshape(-1, 12)
    m = np.zeros((len(flat), 4, 4))
    m[:, :3, :3] = flat[:, :9].reshape(-1, 3, 3)
    m[:, :3, 3] = flat[:, 9:]
    m[:, 3, 3] = 1.0
    return {(r, i): mi for r, i, mi, ok in zip(robot, k, m, kind == "x") if ok}
