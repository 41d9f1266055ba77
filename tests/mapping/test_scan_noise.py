"""Issue 16: the scans' own residual spread (`split_half_sigma`) sets the scale of the
registration checks, so a noisier or sparser sensor than the benchmark's protocol is not refused
for residuals a right registration of its scans has."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from benchmarks.real_views import load_fragment, make_view_pair, perturb
from graphloc.mapping.acceptance import AcceptanceConfig, residual_scale
from graphloc.mapping.registration import RegistrationConfig, pose_errors, prepare
from graphloc.mapping.registration_starts import hint_covariance
from graphloc.mapping.robust_registration import robust_register
from graphloc.mapping.scan_noise import split_half_sigma

CFG = RegistrationConfig()


def _sigma(points: np.ndarray) -> float:
    return split_half_sigma(
        points, CFG.voxel, CFG.normal_radius, CFG.max_nn, CFG.max_correspondence[-1]
    )


def _corner(noise: float, n: int = 60_000, seed: int = 3) -> np.ndarray:
    """A floor and two walls of a 4 m room corner, n points, Gaussian noise of `noise` [m]."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(0.0, 4.0, (n, 2))
    face = rng.integers(0, 3, n)
    pts = np.zeros((n, 3))
    for k, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):  # floor z = 0, walls y = 0, x = 0
        pts[face == k, i], pts[face == k, j] = u[face == k, 0], u[face == k, 1]
    return pts + rng.normal(0.0, noise, pts.shape)


def test_split_half_sigma_grows_with_the_noise_and_is_reproducible():
    sig = [_sigma(_corner(s)) for s in (0.0, 0.005, 0.01, 0.02)]
    assert sig[0] < 0.001  # flat faces without noise: the halves' cells lie on one plane
    assert sig[0] < sig[1] < sig[2] < sig[3]
    # cells average the points they hold: the halves differ by less than the raw noise, and by
    # more than a cell's mean of it would if every cell held many points
    assert 0.0 < sig[3] < 0.02 * np.sqrt(2)
    assert _sigma(_corner(0.01)) == sig[2]  # seeded split and samples


def test_split_half_sigma_of_a_sparser_scan_is_wider():
    for noise in (0.005, 0.01):
        sparse = _sigma(_corner(noise, n=8_000))
        # about one point per cell: two independent noisy points differ by sqrt(2) sigma
        assert sparse == pytest.approx(np.sqrt(2) * noise, rel=0.15)
        # many points per cell: the cells' means differ by less
        assert _sigma(_corner(noise, n=240_000)) < sparse / 1.15


def test_split_half_sigma_without_enough_points_is_nan():
    assert np.isnan(_sigma(np.zeros((4, 3))))
    far = np.vstack([np.zeros((5, 3)), np.full((5, 3), 10.0)])
    assert np.isnan(_sigma(far))  # no half has a neighbour of the other within reach


def test_residual_scale_is_the_pairs_spread_never_below_the_floor():
    cloud = prepare(_corner(0.005, n=20_000))
    assert np.isfinite(cloud.residual_spread) and cloud.residual_spread > 0
    acc = AcceptanceConfig(residual_sigma=0.01)
    wide, narrow = replace(cloud, residual_spread=0.02), replace(cloud, residual_spread=0.004)
    assert residual_scale(wide, narrow, acc) == pytest.approx(np.sqrt((0.02**2 + 0.004**2) / 2))
    assert residual_scale(narrow, narrow, acc) == 0.01
    unmeasured = replace(cloud, residual_spread=float("nan"))
    assert residual_scale(unmeasured, wide, acc) == 0.01
    # prepared only for consecutive scan matching: no spread measured, no polish points kept
    plain = prepare(_corner(0.005, n=20_000), inter_robot=False)
    assert np.isnan(plain.residual_spread) and plain.raw is None


def test_a_noisier_sensors_right_registration_is_fused():
    """Views with twice the protocol's noise (1 cm): at the fixed scale of 1 cm the right pose's
    inlier ratio falls below the floor and it is refused; at the scans' own spread it is fused."""
    rng = np.random.default_rng(200)
    pair = make_view_pair(load_fragment(), 0.6, rng, noise_m=0.01)
    source, target = prepare(pair.ceiling), prepare(pair.ground)
    hint = perturb(pair.T_ground_ceiling, 3.0, 0.05, rng)
    cov = hint_covariance(np.deg2rad(3.0), 0.05)
    d = robust_register(source, target, hint, cov)
    assert d.residual_scale > 0.012 and d.as_dict()["residual_scale_m"] == d.residual_scale
    rot, trans = pose_errors(d.registration.transformation, pair.T_ground_ceiling)
    assert d.accepted and rot < 0.5 and trans < 0.02, (d.reasons, rot, trans)
    nan = float("nan")
    fixed = robust_register(
        replace(source, residual_spread=nan), replace(target, residual_spread=nan), hint, cov
    )
    assert fixed.residual_scale == AcceptanceConfig().residual_sigma
    assert not fixed.accepted
    assert [k for k, v in fixed.checks.items() if not v[2]] == ["inlier_ratio"]
