"""The HypothesisTracker's track type (`Track`: one Gaussian hypothesis), the Student-t fit score
of an association (`fit_score`) and the covariance cap (`cap_covariances`); its settings are
`graphloc.hypotheses.config.TrackerConfig`."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np


def fit_score(maha: np.ndarray, dof: float, dim: int = 6) -> np.ndarray:
    """Log-density of the innovation's Mahalanobis^2 under a multivariate Student-t with `dof`
    degrees of freedom (Gaussian for dof = inf), relative to its value at maha = dim (the mean
    of chi2_dim): 0 for a typical consistent association, the scale of a coasting track."""
    if np.isinf(dof):
        return -0.5 * (maha - dim)
    return -0.5 * (dof + dim) * (np.log1p(maha / dof) - np.log1p(dim / dof))


def cap_covariances(cov: np.ndarray, max_std: float) -> np.ndarray:
    """(K,n,n) covariances with eigenvalues clipped at max_std^2 (batched eigh)."""
    if not len(cov):
        return cov
    w, V = np.linalg.eigh(cov)
    return np.einsum("kij,kj,klj->kil", V, np.minimum(w, max_std**2), V)


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
