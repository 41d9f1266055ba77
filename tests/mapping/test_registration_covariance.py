"""Issue 16: the registration covariance model -- the cluster-robust sandwich
(`cluster_covariance`) of per-point influences (`least_squares_influence`, the polish's
`polish_influence`), its degeneracy term (`degeneracy_term`) and their calibration
(`fit_calibration`), on synthetic point-to-plane problems with known answers and on the real
fragment."""

from __future__ import annotations

from dataclasses import replace

import gtsam
import numpy as np
import pytest

from benchmarks.fusion_calibration import fit_calibration
from benchmarks.real_views import load_fragment, make_view_pair
from graphloc.mapping.acceptance import AcceptanceConfig
from graphloc.mapping.registration import RegistrationConfig, prepare
from graphloc.mapping.registration_covariance import (
    cluster_covariance,
    degeneracy_term,
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


def test_fit_calibration_recovers_the_scale_and_the_degeneracy_term_of_synthetic_errors():
    """Errors drawn from N(0, s (P_i + c Q_i)) with s = 3, c = 4, P_i of different sizes and Q_i
    rank-one terms along random directions, large in a third of the trials: the maximum-likelihood
    s and c are close, their 95% intervals hold them, the fit beats the scale alone (c = 0), and
    a wrong (s, c) has a larger -2 log-likelihood."""
    rng = np.random.default_rng(11)
    n = 600
    A = rng.normal(size=(n, 6, 6)) * np.geomspace(1e-4, 1e-2, n)[:, None, None]
    P = A @ A.transpose(0, 2, 1) + 1e-10 * np.eye(6)
    u = rng.normal(size=(n, 6))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    var = np.einsum("ni,nij,nj->n", u, P, u) * np.where(np.arange(n) % 3 == 0, 2.0, 0.02)
    Q = var[:, None, None] * np.einsum("ni,nj->nij", u, u)
    cov = 3.0 * (P + 4.0 * Q)
    e = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.normal(size=(n, 6)))
    fit = fit_calibration(e, P, Q)
    assert fit["covariance_scale"] == pytest.approx(3.0, rel=0.1)
    assert fit["covariance_degeneracy"] == pytest.approx(4.0, rel=0.3)
    lo, hi = fit["covariance_scale_95"]
    assert lo < fit["covariance_scale"] < hi and hi < 2 * lo
    lo, hi = fit["covariance_degeneracy_95"]
    assert lo < 4.0 < hi
    assert fit["scale_alone"]["nll"] > fit["nll"] + 10.0

    def nll(s, c):
        q = np.einsum("ni,ni->n", e, np.linalg.solve(s * (P + c * Q), e[..., None])[..., 0])
        return np.linalg.slogdet(s * (P + c * Q))[1].sum() + q.sum()

    assert nll(2.0, 4.0) > fit["nll"] and nll(3.0, 1.0) > fit["nll"]
    assert nll(fit["covariance_scale"], fit["covariance_degeneracy"]) == pytest.approx(fit["nll"])
    # errors with no degeneracy term: c comes out near 0, the scale alone as good
    e0 = np.einsum("nij,nj->ni", np.linalg.cholesky(3.0 * P), rng.normal(size=(n, 6)))
    fit0 = fit_calibration(e0, P, Q)
    assert fit0["covariance_degeneracy_95"][0] == 0.0
    assert fit0["scale_alone"]["nll"] - fit0["nll"] < 3.84
    with pytest.raises(ValueError, match="fit_calibration"):
        fit_calibration(e[:, :3], P, Q)
    with pytest.raises(ValueError, match="fit_calibration"):
        fit_calibration(e, P, Q[:-1])


def test_degeneracy_term_inflates_the_directions_the_views_hardly_constrain():
    """A Hessian whose rotation about z (in metres at the scale) is held min_conditioning as
    strongly as the best direction: Q along it is the sandwich's own variance there (weight one
    at the threshold), and a hundred times less along a direction constrained a hundred times
    better; a well-conditioned Hessian leaves Q about min_conditioning times P; rotations
    weigh in metres at scale_m."""
    scale, least = 2.0, 1e-4
    d = np.array([1 / scale] * 3 + [1.0] * 3)
    lam = np.array([1.0, 1.0, least, 1.0, 1e-2, 1.0]) * 1e6  # scaled: rot z weakest, t y weak
    H = np.diag(lam / d**2)  # D H D = diag(lam)
    P = np.diag([4e-6, 5e-6, 6e-6, 1e-6, 2e-6, 3e-6])
    Q = degeneracy_term(P, H, scale, least)
    np.testing.assert_allclose(Q, np.diag(least * lam.max() / lam * np.diag(P)), atol=1e-20)
    assert Q[2, 2] == pytest.approx(P[2, 2]) and Q[4, 4] == pytest.approx(1e-2 * P[4, 4])
    Qw = degeneracy_term(P, np.diag(1e6 / d**2), scale, least)
    np.testing.assert_allclose(Qw, least * P, rtol=1e-9, atol=1e-20)
    singular = np.diag([1.0] * 5 + [0.0])
    with pytest.raises(ValueError, match="degeneracy_term"):
        degeneracy_term(P, singular, scale, least)
    assert not degeneracy_term(P, singular, scale, 0.0).any()  # no threshold: no inflation
    with pytest.raises(ValueError, match="min_conditioning"):
        AcceptanceConfig(min_conditioning=-least)
    with pytest.raises(ValueError, match="degeneracy_term"):
        degeneracy_term(P, H, 0.0, least)


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
