"""The HypothesisTracker's track type (`Track`: one Gaussian hypothesis), the Student-t fit score
of an association (`fit_score`), the covariance cap (`cap_covariances`) and a frame's candidate
covariances, checked and capped (`capped_candidate_covariances`); its settings are
`graphloc.hypotheses.config.TrackerConfig`."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.mixture import candidate_covariances
from graphloc.hypotheses.config import TrackerConfig


def fit_score(maha: np.ndarray, dof: float, dim: int = 6) -> np.ndarray:
    """Log-density of the innovation's Mahalanobis^2 under a multivariate Student-t with `dof`
    degrees of freedom (Gaussian for dof = inf), relative to its value at maha = dim (the mean
    of chi2_dim): 0 for a typical consistent association, the scale of a coasting track."""
    if np.isinf(dof):
        return -0.5 * (maha - dim)
    return -0.5 * (dof + dim) * (np.log1p(maha / dof) - np.log1p(dim / dof))


def cap_covariances(cov: np.ndarray, max_std: float) -> np.ndarray:
    """(K,n,n) covariances with eigenvalues clipped at max_std^2 (batched eigh; a covariance
    whose trace is at most max_std^2 has no eigenvalue above it and is returned as it is)."""
    over = np.trace(cov, axis1=1, axis2=2) > max_std**2
    if not over.any():
        return cov
    w, V = np.linalg.eigh(cov[over])
    cov = cov.copy()
    cov[over] = np.einsum("kij,kj,klj->kil", V, np.minimum(w, max_std**2), V)
    return cov


def capped_candidate_covariances(candidates: CandidateSet, config: TrackerConfig) -> np.ndarray:
    """A frame's candidate covariances (`factors.mixture.candidate_covariances`: the set's,
    else the default sigmas) capped at max_candidate_std; finite and symmetric (else the
    ValueError of `candidate_covariances`, naming the set); `log_determinants` checks that
    they are positive definite."""
    given = candidates.covariance
    if given is None:
        given = candidates.meta.get("covariance")
    cov = None if given is None else np.asarray(given, dtype=float)
    if (
        cov is None
        or cov.shape != (len(candidates), 6, 6)
        or not np.isfinite(cov).all()
        or np.abs(cov - cov.transpose(0, 2, 1)).max(initial=0.0) > 1e-9
    ):  # the default, or a set to be checked by the rule and message of candidate_covariances
        cov = candidate_covariances(candidates, config.default_sigmas)
    return cap_covariances(cov, config.max_candidate_std)


def log_determinants(
    stack: np.ndarray, candidates: CandidateSet, config: TrackerConfig
) -> np.ndarray:
    """log det of every matrix of `stack` (M,6,6), whose first len(candidates) are the
    candidates' covariances: one Cholesky factorization, which is also the check that they are
    positive definite (the ValueError of `candidate_covariances`, naming the set)."""
    try:
        chol = np.linalg.cholesky(stack)
    except np.linalg.LinAlgError:  # not positive definite: the message, else a closer look
        candidate_covariances(candidates, config.default_sigmas)
        return np.linalg.slogdet(stack)[1]
    return 2.0 * np.log(np.einsum("kii->ki", chol)).sum(axis=1)


@dataclass
class Track:
    """One hypothesis: Gaussian on the camera pose (mean, 6x6 covariance in GTSAM's tangent
    order), log-weight, the lineage id that survives coasting frames, the candidate it sits on."""

    mean: gtsam.Pose3
    cov: np.ndarray
    logw: float
    track_id: int
    candidate: int  # index into the current frame's candidates, -1 when coasting
    misses: int = 0
