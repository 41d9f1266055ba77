"""P3P candidate mixture: one discrete mode per observation (`keys.mode_key`), one Gaussian
component per candidate pose (seed 000 Sec. III-B / V: up to four P3P solutions, one genuine;
seed 004 Sec. II-C: the same ambiguity).

Component k is `BetweenFactorPose3(observer, observed, T_k)` -- or `PriorFactorPose3(observed,
T_k)` when the observer is the world (ground robots localized beforehand, seed 000 Sec. III-A)
-- with the candidate's covariance. `candidate_mixture` wraps them in GTSAM 4.3's
`HybridNonlinearFactor`; the scalar of component k is -log w_k + the Gaussian's negative log
normalizer, so the factor's error is the negative log of a properly weighted Gaussian mixture.

Candidate covariances: `CandidateSet.meta["covariance"]` (K,6,6) when the front-end provides
it (e.g. `graphloc.datasets.feng.resection_covariance`), else `default_sigmas` (rot [rad],
trans [m]); GTSAM Pose3 tangent order (rx, ry, rz, tx, ty, tz).
"""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.robust import Kernel, robust_noise
from graphloc.keys import mode_key


def candidate_covariances(candidates: CandidateSet, default_sigmas=(0.02, 0.05)) -> np.ndarray:
    """(K,6,6) covariance of every candidate: meta["covariance"] if present, else diagonal."""
    k = len(candidates)
    cov = candidates.meta.get("covariance")
    if cov is None:
        rot, trans = (float(s) for s in default_sigmas)
        if not (rot > 0 and trans > 0):
            raise ValueError(f"candidate_covariances: default sigmas must be > 0, got {default_sigmas}")
        return np.broadcast_to(np.diag([rot ** 2] * 3 + [trans ** 2] * 3), (k, 6, 6)).copy()
    cov = np.asarray(cov, dtype=float)
    if cov.shape != (k, 6, 6):
        raise ValueError(f"CandidateSet.meta['covariance'] must be ({k},6,6), got {cov.shape} "
                         f"(source={candidates.source!r}, time={candidates.time})")
    check_covariances(cov, f"CandidateSet.meta['covariance'] (source={candidates.source!r}, time={candidates.time})")
    return cov


def check_covariances(cov: np.ndarray, what: str) -> None:
    """Batched check of (K,n,n) covariances: finite, symmetric, positive definite (ValueError
    naming the first bad index)."""
    if not np.isfinite(cov).all():
        raise ValueError(f"{what}: contains NaN/inf")
    asym = np.abs(cov - np.swapaxes(cov, -1, -2)).max(axis=(-2, -1)) if cov.size else np.zeros(0)
    bad = np.nonzero(asym > 1e-9 * np.maximum(1.0, np.abs(cov).max(axis=(-2, -1))))[0]
    if bad.size:
        raise ValueError(f"{what}[{bad[0]}]: not symmetric")
    bad = np.nonzero(np.linalg.eigvalsh(cov)[..., 0] <= 0)[0] if cov.size else bad
    if bad.size:
        raise ValueError(f"{what}[{bad[0]}]: not positive definite")


def component_factors(candidates: CandidateSet, observed_key: int, observer_key: int | None = None,
                      covariances: np.ndarray | None = None, kernel: Kernel = Kernel()) -> list[gtsam.NoiseModelFactor]:
    """One factor per candidate: BetweenFactorPose3(observer, observed, T_k) or, with
    observer_key None, PriorFactorPose3(observed, T_k); Gaussian noise from `covariances`,
    optionally robust (`factors.robust.Kernel`)."""
    cov = candidate_covariances(candidates) if covariances is None else np.asarray(covariances, dtype=float)
    if cov.shape != (len(candidates), 6, 6):
        raise ValueError(f"component_factors: covariances must be ({len(candidates)},6,6), got {cov.shape}")
    out = []
    for pose, c in zip(candidates.poses(), cov):
        noise = robust_noise(gtsam.noiseModel.Gaussian.Covariance(c), kernel)
        if observer_key is None:
            out.append(gtsam.PriorFactorPose3(observed_key, pose, noise))
        else:
            out.append(gtsam.BetweenFactorPose3(observer_key, observed_key, pose, noise))
    return out


def candidate_mixture(candidates: CandidateSet, observation: int, observed_key: int,
                      observer_key: int | None = None, covariances: np.ndarray | None = None
                      ) -> gtsam.HybridNonlinearFactor:
    """HybridNonlinearFactor over mode_key(observation) with one component per candidate and
    component weights w = candidates.weights() (from the scores). Zero-weight candidates get a
    large finite penalty (GTSAM needs finite scalars)."""
    if len(candidates) == 0:
        raise ValueError(f"candidate_mixture: observation {observation} has no candidates")
    factors = component_factors(candidates, observed_key, observer_key, covariances)
    w = candidates.weights()
    with np.errstate(divide="ignore"):
        neg_log_w = np.where(w > 0, -np.log(np.maximum(w, 1e-300)), 1e6)
    pairs = [(f, float(nlw + f.noiseModel().negLogConstant())) for f, nlw in zip(factors, neg_log_w)]
    return gtsam.HybridNonlinearFactor((mode_key(observation), len(candidates)), pairs)
