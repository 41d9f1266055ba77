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


def grids_rows(grids: list) -> list:
    """`grid_rows` of every grid of a list (one vectorized pass over all of them)."""
    if not grids:
        return []
    rows = grid_rows(np.concatenate(grids)) if sum(map(len, grids)) else np.zeros((0, 7))
    return np.split(rows, np.cumsum([len(g) for g in grids])[:-1])


def pose_grids(node_times: list, robot, index, m: np.ndarray) -> list:
    """Per robot r, a (K_r,3,4) grid of [R | t]: m[i] ((N,3,4) or (N,4,4)) at row index[i] of
    robot[i]'s grid, NaN where no pose is given (`grid_rows` makes them rows)."""
    robot, index = np.asarray(robot, dtype=int), np.asarray(index, dtype=int)
    grids = [np.full((len(times), 3, 4), np.nan) for times in node_times]
    for r, grid in enumerate(grids):
        mine = robot == r
        grid[index[mine]] = m[mine, :3]
    return grids


def values_poses(values: gtsam.Values) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(robot, index, (N,3,4) [R | t]) of every robot pose in `values` (one `extractPose3`)."""
    poses = gtsam.utilities.allPose3s(values)
    kind, robot, index = decode_many(poses.keys())
    flat = gtsam.utilities.extractPose3(poses).reshape(-1, 12)
    m = np.concatenate([flat[:, :9].reshape(-1, 3, 3), flat[:, 9:, None]], axis=2)
    pose = kind == "x"
    return robot[pose], index[pose], m[pose]
