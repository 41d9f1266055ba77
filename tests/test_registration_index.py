"""The nearest-neighbour index of the registration checks and the polish (`NearestIndex`: a
fixed-radius hash-grid search) and the reproducible prepared clouds (`prepare` sorts Open3D's
voxel cells, whose order otherwise changes from call to call)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from graphloc.mapping.registration import RegistrationConfig, prepare
from graphloc.mapping.registration_index import NearestIndex


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
