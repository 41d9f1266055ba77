"""A scan's own point-to-plane residual spread (issue 16): what two views of one surface differ
by at the true pose, measured on the scan alone, so that the acceptance checks of
`graphloc.mapping.acceptance` scale with the sensor's noise and the scan's density instead of a
fixed number (`split_half_sigma`), and the voxel grid every prepared cloud is built on
(`grid_cells`)."""

from __future__ import annotations

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation

from graphloc.mapping.registration_index import NearestIndex

# the second half's frame: a fixed, generic rotation, so that its voxel grid cuts the surfaces
# differently from the first half's, as a second robot's grid does
_SPLIT_ROTATION = Rotation.from_rotvec([0.4, -0.7, 1.1]).as_matrix()


def grid_cells(points: np.ndarray, voxel: float) -> np.ndarray:
    """(N,3) points on a grid of `voxel` (each occupied cell's centroid, Open3D), sorted by x,
    then y, then z: Open3D's voxel hash map hands the cells back in an order that changes from
    call to call (the same points), so every index-based step after it is reproducible only
    sorted."""
    cells = o3d.t.geometry.PointCloud(o3d.core.Tensor(points)).voxel_down_sample(voxel)
    cells = cells.point.positions.numpy()
    return cells[np.lexsort(cells.T[::-1])]


def split_half_sigma(
    points: np.ndarray,
    voxel: float,
    normal_radius: float,
    max_nn: int,
    max_distance: float,
    samples: int = 2000,
    seed: int = 0,
) -> float:
    """The point-to-plane residual spread [m] between two independent halves of one scan at their
    known relative pose (each gridded at `voxel`, B turned by a fixed rotation): 1.4826 times the
    median absolute residual of up to `samples` of A's cells (seeded) to B's nearest cell's plane
    within `max_distance`; two robots' views of one surface differ by the same noise and
    sampling. NaN when fewer than 10 of the samples have a neighbour."""
    pts = np.asarray(points, dtype=np.float64)
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(pts))
    half = len(pts) // 2
    if half < 3:
        return float("nan")
    a = grid_cells(pts[order[:half]], voxel)
    b = grid_cells(pts[order[half:]] @ _SPLIT_ROTATION.T, voxel)
    if len(a) > samples:
        a = a[rng.choice(len(a), samples, replace=False)]
    a = a @ _SPLIT_ROTATION.T  # into B's frame
    j, _ = NearestIndex(b, max_distance).nearest(a)
    has = j >= 0
    if has.sum() < 10:
        return float("nan")
    a, j = a[has], j[has]
    # the max_nn nearest of B's cells within normal_radius of each matched cell (Open3D's k-d
    # tree; a radius search walks every cell within the radius, slow on dense scans), their
    # covariance (offsets from the matched cell, one batched product), and its least
    # eigenvector the normal
    nns = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor(b))
    nns.knn_index()
    nb, d2 = nns.knn_search(o3d.core.Tensor(b[j]), min(max_nn, len(b)))
    nb = nb.numpy()
    w = (d2.numpy() <= normal_radius**2)[..., None]
    q = (b[nb] - b[j][:, None]) * w
    n = w.sum(axis=1)[:, :, None]
    m = q.sum(axis=1)[:, :, None] / n
    _, vec = np.linalg.eigh(q.transpose(0, 2, 1) @ q - n * (m @ m.transpose(0, 2, 1)))
    r = np.einsum("ij,ij->i", a - b[j], vec[:, :, 0])  # the smallest eigenvalue's direction
    return float(1.4826 * np.median(np.abs(r)))
