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


def test_polish_voxel_grids_the_polish_points_and_zero_keeps_them():
    """RegistrationConfig.polish_voxel bounds the polish's points on dense scans: the input on
    that grid (one centroid per occupied cell, sorted, the same every call); 0 (the default)
    keeps every input point."""
    rng = np.random.default_rng(8)
    pts = np.c_[rng.uniform(0, 2, (30000, 2)), rng.normal(0, 0.002, 30000)]
    keep_all = prepare(pts, RegistrationConfig())
    np.testing.assert_array_equal(keep_all.raw, pts)
    cfg = RegistrationConfig(polish_voxel=0.02)
    a, b = prepare(pts, cfg), prepare(pts, cfg)
    np.testing.assert_array_equal(a.raw, b.raw)
    assert len(a.raw) < len(pts) and np.all(np.lexsort(a.raw.T[::-1]) == np.arange(len(a.raw)))
    # one centroid per occupied cell of the grid anchored at the origin
    occupied = np.unique(np.floor(pts / 0.02).astype(int), axis=0)
    assert len(np.unique(np.floor(a.raw / 0.02).astype(int), axis=0)) == len(a.raw)
    assert len(a.raw) == len(occupied)
    with pytest.raises(ValueError, match="polish_voxel"):
        RegistrationConfig(polish_voxel=-0.01)
