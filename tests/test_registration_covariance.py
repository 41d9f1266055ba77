"""Issue 16: the registration covariance model -- the cluster-robust sandwich
(`cluster_covariance`) of per-point influences (`least_squares_influence`, the polish's
`polish_influence`) and its one-parameter calibration (`fit_calibration`), on synthetic
point-to-plane problems with known answers and on the real fragment."""

from __future__ import annotations

from dataclasses import replace

import gtsam
import numpy as np
import pytest

from graphloc.experiments.fusion_calibration import fit_calibration
from graphloc.experiments.real_views import load_fragment, make_view_pair
from graphloc.mapping.registration import RegistrationConfig, prepare
from graphloc.mapping.registration_covariance import (
    cluster_covariance,
    least_squares_influence,
    polish_influence,
)
from graphloc.mapping.registration_stages import polish


def _problem(rng, n, sigma, extent):
    """n points uniform in a cube of side `extent`, random unit normals, J = [p x n, n],
    independent residuals of std sigma."""
    p = rng.uniform(0.0, extent, (n, 3))
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    J = np.hstack([np.cross(p, nrm), nrm])
    return J, rng.normal(0.0, sigma, n), p


def test_sandwich_matches_the_textbook_covariance_for_many_independent_clusters():
    """Independent residuals in many clusters: the cluster sandwich estimates sigma^2 H^-1
    (within the sampling error of a few hundred clusters)."""
    rng = np.random.default_rng(3)
    J, r, p = _problem(rng, 20_000, 0.005, 4.0)
    H = J.T @ J
    cov = cluster_covariance(least_squares_influence(J, r), p, 0.5)
    ratio = np.diag(cov) / np.diag(0.005**2 * np.linalg.inv(H))
    assert np.all(np.abs(ratio - 1.0) < 0.3), ratio
    assert np.allclose(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_sandwich_follows_residuals_correlated_within_a_cluster():
    """Residuals that share an offset per block (a surface one view samples differently, seen
    by all its points): the least-squares pose's spread over many draws is several times
    sigma^2 H^-1 of the residuals' own variance; the cluster sandwich over those blocks, averaged
    over the draws, follows the spread, and one over blocks far smaller than the correlated
    ones misses it as the textbook covariance does."""
    rng = np.random.default_rng(7)
    block = 0.5
    p = rng.uniform(0.0, 3.0, (4000, 3))
    label = np.unique(np.floor(p / block).astype(int), axis=0, return_inverse=True)[1].ravel()
    nrm = rng.normal(size=(label.max() + 1, 3))[label]  # one surface (normal) per block
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    J = np.hstack([np.cross(p, nrm), nrm])
    H = J.T @ J
    H_inv = np.linalg.inv(H)
    deltas, sandwich, fine, textbook = [], [], [], []
    for _ in range(300):
        r = rng.normal(0.0, 0.003, label.max() + 1)[label] + rng.normal(0.0, 0.003, len(p))
        deltas.append(H_inv @ (J.T @ r))
        psi = least_squares_influence(J, r)
        sandwich.append(cluster_covariance(psi, p, block))
        fine.append(cluster_covariance(psi, p, 0.05))
        textbook.append(np.var(r) * H_inv)
    spread = np.cov(np.array(deltas).T)

    def ratio(cov):
        return np.trace(np.linalg.solve(spread, np.mean(cov, axis=0))) / 6

    assert ratio(sandwich) == pytest.approx(1.0, abs=0.25)
    assert ratio(textbook) < 0.3 and ratio(fine) < 0.3


def test_cluster_covariance_rejects_mismatched_shapes():
    J, r, p = _problem(np.random.default_rng(0), 50, 0.01, 1.0)
    with pytest.raises(ValueError, match="cluster_covariance"):
        cluster_covariance(least_squares_influence(J, r)[:-1], p, 0.5)
    assert least_squares_influence(J[:5], r[:5]) is None  # fewer rows than unknowns


def test_fit_calibration_recovers_the_scale_of_synthetic_errors():
    """Errors drawn from N(0, s P_i) with s = 3 and P_i of different sizes: the maximum-likelihood
    scale is close to 3, its 95% interval holds it, and a wrong scale has a larger negative
    log-likelihood."""
    rng = np.random.default_rng(11)
    n = 400
    A = rng.normal(size=(n, 6, 6)) * np.geomspace(1e-4, 1e-2, n)[:, None, None]
    P = A @ A.transpose(0, 2, 1) + 1e-10 * np.eye(6)
    e = np.einsum("nij,nj->ni", np.linalg.cholesky(3.0 * P), rng.normal(size=(n, 6)))
    fit = fit_calibration(e, P)
    assert fit["covariance_scale"] == pytest.approx(3.0, rel=0.1)
    lo, hi = fit["covariance_scale_95"]
    assert lo < 3.0 < hi
    q = np.einsum("ni,ni->n", e, np.linalg.solve(P, e[..., None])[..., 0])
    _, logdet = np.linalg.slogdet(2.0 * P)
    assert logdet.sum() + q.sum() / 2.0 > fit["nll"]
    with pytest.raises(ValueError, match="fit_calibration"):
        fit_calibration(e[:, :3], P)


@pytest.mark.parametrize("seed,overlap", [(3, 0.6), (4, 0.3), (5, 0.6)])
def test_polish_influences_sum_to_a_step_along_the_polish_round(seed, overlap):
    """The real fragment's views, the settled polish moved by a few of its sigmas: the
    influences of both directions (their signs, the backward direction's adjoint and the
    midpoint's half) sum to the midpoint's Gauss-Newton step with the correspondences held, which
    points where one polish round of Open3D's ICP goes and covers part of the way (ICP chooses
    the nearest neighbours again as the pose moves; the calibrated scale carries the rest)."""
    cfg = RegistrationConfig()
    pair = make_view_pair(load_fragment(), overlap, np.random.default_rng(seed))
    source, target = prepare(pair.ceiling, cfg), prepare(pair.ground, cfg)
    settled = polish(source, target, pair.T_ground_ceiling, cfg)
    T = settled.transformation
    V = cluster_covariance(*polish_influence(settled.views, T, cfg), cfg.covariance_block)
    W = np.linalg.inv(V)
    rng = np.random.default_rng(seed)
    for _ in range(2):
        T1 = gtsam.Pose3.Expmap(4.0 * np.linalg.cholesky(V) @ rng.normal(size=6)).matrix() @ T
        one = polish(source, target, T1, replace(cfg, polish_rounds=1))
        went = gtsam.Pose3.Logmap(gtsam.Pose3(one.transformation @ np.linalg.inv(T1)))
        psi, points = polish_influence(one.views, T1, cfg)
        assert psi.shape == (len(points), 6)
        step = psi.sum(axis=0)
        cos = (step @ W @ went) / np.sqrt((step @ W @ step) * (went @ W @ went))
        length = np.sqrt((step @ W @ step) / (went @ W @ went))
        assert cos > 0.8, cos
        assert 0.3 < length < 0.9, length
