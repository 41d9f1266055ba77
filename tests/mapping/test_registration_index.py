"""The nearest-neighbour index of the registration checks and the polish (`NearestIndex`: a
fixed-radius hash-grid search) and the reproducible prepared clouds (`prepare` sorts Open3D's
voxel cells, whose order otherwise changes from call to call)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from graphloc.mapping.registration import RegistrationConfig, prepare
from graphloc.mapping.registration_index import NearestIndex
from graphloc.mapping.scan_noise import grid_cells


def test_nearest_index_is_the_nearest_point_within_its_radius():
    rng = np.random.default_rng(3)
    points = rng.uniform(0.0, 1.0, (4000, 3))
    query = rng.uniform(-0.1, 1.1, (3000, 3))
    radius = 0.04
    idx, d = NearestIndex(points, radius).nearest(query)
    d_ref, idx_ref = cKDTree(points).query(query)
    near = d_ref < radius
    assert 0.2 < near.mean() < 0.9  # both cases occur
    np.testing.assert_array_equal(idx[near], idx_ref[near])
    np.testing.assert_allclose(d[near], d_ref[near], rtol=1e-12, atol=1e-12)
    assert np.all(idx[~near] == -1) and np.all(np.isinf(d[~near]))
    with pytest.raises(ValueError, match="radius"):
        NearestIndex(points, 0.0)


def test_prepare_is_reproducible_and_sorted():
    """Open3D's voxel hash map hands its cells back in an order that changes between calls on
    the same points; `prepare` sorts them, so the every-k-th samples of the fine stage (and every
    result) repeat exactly."""
    rng = np.random.default_rng(5)
    floor = np.c_[rng.uniform(0, 4, (20000, 2)), rng.normal(0, 0.005, 20000)]
    wall = np.c_[rng.uniform(0, 4, 20000), rng.normal(2, 0.005, 20000), rng.uniform(0, 2, 20000)]
    pts = np.vstack([floor, wall])
    cfg = RegistrationConfig()
    a, b = prepare(pts, cfg), prepare(pts, cfg)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.cloud.point.normals.numpy(), b.cloud.point.normals.numpy())
    p = a.points
    assert np.all(np.lexsort(p.T[::-1]) == np.arange(len(p)))  # x, then y, then z


def test_polish_points_per_cell_strides_dense_scans_and_keeps_sparse_ones():
    """RegistrationConfig.polish_points_per_cell bounds the polish's points on dense scans: every
    k-th input point with the smallest k leaving at most that many per occupied grid cell; a
    scan with fewer per cell, or 0, keeps every input point."""
    rng = np.random.default_rng(8)
    pts = np.c_[rng.uniform(0, 2, (30000, 2)), rng.normal(0, 0.002, 30000)]
    cells = len(prepare(pts, RegistrationConfig(polish_points_per_cell=0)).points)
    assert len(pts) > 3 * cells  # several points per 3 cm cell
    off = prepare(pts, RegistrationConfig(polish_points_per_cell=0)).raw
    np.testing.assert_array_equal(off, pts)
    np.testing.assert_array_equal(
        prepare(pts, RegistrationConfig(polish_points_per_cell=8)).raw, pts
    )
    strided = prepare(pts, RegistrationConfig(polish_points_per_cell=2)).raw
    k = -(-len(pts) // (2 * cells))
    assert k > 1 and len(strided) <= 2 * cells
    np.testing.assert_array_equal(strided, pts[::k])
    with pytest.raises(ValueError, match="polish_points_per_cell"):
        RegistrationConfig(polish_points_per_cell=-1)


def test_a_scan_denser_than_max_points_per_cell_is_thinned_at_random_to_it():
    """RegistrationConfig.max_points_per_cell: a scan with more input points per occupied grid
    cell on average is gridded from that many per cell, the same random draw in every call
    (no stride: an organized scan's every k-th point can be one column); a sparser scan, or 0,
    keeps every point; the polish's points and the residual spread come from the points kept."""
    rng = np.random.default_rng(9)
    pts = np.c_[rng.uniform(0, 1, (60000, 2)), rng.normal(0, 0.002, 60000)]
    whole = prepare(pts, RegistrationConfig(max_points_per_cell=0))
    cells = len(grid_cells(pts, RegistrationConfig().voxel))  # before the outlier removal
    assert len(pts) > 20 * cells and whole.n_used == len(pts)  # about 25 per 3 cm cell
    np.testing.assert_array_equal(
        prepare(pts, RegistrationConfig(max_points_per_cell=100)).points, whole.points
    )
    cfg = RegistrationConfig(max_points_per_cell=8, polish_points_per_cell=0)
    a, b = prepare(pts, cfg), prepare(pts, cfg)
    assert a.n_input == len(pts) and a.n_used == int(8 * cells)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.raw, b.raw)
    # the points kept, in their input order, spread over the whole scan
    pos = np.flatnonzero(np.isin(pts[:, 0], a.raw[:, 0]))
    assert len(pos) == a.n_used and np.all(np.diff(pos) > 0)
    np.testing.assert_array_equal(a.raw, pts[pos])
    assert np.ptp(np.diff(pos)) > 1  # not a stride
    assert abs(len(a.points) - len(whole.points)) < 0.05 * cells  # the same surface and grid
    with pytest.raises(ValueError, match="max_points_per_cell"):
        RegistrationConfig(max_points_per_cell=-1)
