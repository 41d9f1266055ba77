"""Issue 16: the registration covariance model -- the leave-one-cluster-out jackknife
(`cluster_covariance`) and its one-parameter calibration (`fit_calibration`), on synthetic
point-to-plane problems with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from graphloc.experiments.fusion_calibration import fit_calibration
from graphloc.mapping.registration_covariance import cluster_covariance


def _problem(rng, n, sigma, extent):
    """n points uniform in a cube of side `extent`, random unit normals, J = [p x n, n],
    independent residuals of std sigma."""
    p = rng.uniform(0.0, extent, (n, 3))
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    J = np.hstack([np.cross(p, nrm), nrm])
    return J, rng.normal(0.0, sigma, n), p


def test_jackknife_matches_the_textbook_covariance_for_many_independent_clusters():
    """Independent residuals in many clusters: the jackknife estimates sigma^2 H^-1 (within the
    sampling error of a few hundred clusters)."""
    rng = np.random.default_rng(3)
    J, r, p = _problem(rng, 20_000, 0.005, 4.0)
    H = J.T @ J
    cov = cluster_covariance(J, r, p, H, 0.5)
    ratio = np.diag(cov) / np.diag(0.005**2 * np.linalg.inv(H))
    assert np.all(np.abs(ratio - 1.0) < 0.3), ratio
    assert np.allclose(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_jackknife_inflates_more_when_there_are_fewer_clusters():
    """The same independent residuals grouped into fewer, larger clusters (fewer clusters, more
    leverage each): the jackknife's mean inflation over sigma^2 H^-1, averaged over draws, grows,
    the small-sample correction the plain sandwich lacks."""
    rng = np.random.default_rng(5)

    def mean_ratio(block):
        out = []
        for _ in range(30):
            J, r, p = _problem(rng, 3000, 0.005, 3.0)
            H = J.T @ J
            cov = cluster_covariance(J, r, p, H, block)
            out.append(np.trace(np.linalg.solve(0.005**2 * np.linalg.inv(H), cov)) / 6)
        return float(np.mean(out))

    many, few = mean_ratio(0.5), mean_ratio(1.5)  # 216 against 8 clusters
    assert many == pytest.approx(1.0, abs=0.15)
    assert few > 1.3 * many


def test_cluster_covariance_rejects_mismatched_shapes():
    J, r, p = _problem(np.random.default_rng(0), 50, 0.01, 1.0)
    with pytest.raises(ValueError, match="cluster_covariance"):
        cluster_covariance(J, r[:-1], p, J.T @ J, 0.5)


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
