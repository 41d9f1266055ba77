"""Settings and state types of the HypothesisTracker (graphloc.hypotheses.tracker): its
config, one Gaussian track, the Student-t fit score of an association and the covariance cap."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from graphloc.config import check


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


@dataclass(frozen=True)
class TrackerConfig:
    """max_hypotheses: K live tracks. commit_threshold / release_threshold: posterior to commit
    a candidate / below which the committed track is released (0.5: another explanation has
    become more likely than it). full_count: candidates of a complete frame (P3P: 4).
    A frame with J < full_count candidates lacks full_count - J solutions, each equally likely
    the genuine one: a coasting track has prior 1/full_count, a present candidate j w_j J /
    full_count. A complete frame contains the genuine solution (P3P solutions vanish in pairs
    only when the count drops): coasting prior miss_probability_full. birth_probability: prior
    of a track starting at a candidate without a parent.
    max_misses: frames a track may coast. gate: Mahalanobis^2 beyond which a pair is not
    scored. max_candidate_std: cap on the candidate covariance eigenvalues (sqrt, m or rad).
    default_sigmas: candidate (rot, trans) sigmas when the CandidateSet carries no covariances.
    student_dof: degrees of freedom nu of the innovation's Student-t (inf = Gaussian): P3P
    errors are heavy-tailed (near its danger cylinder), so one bad frame must not decide.
    gn_iterations: Gauss-Newton iterations of the window update. robust_commit: commit only if
    the posterior passes commit_threshold without the track's largest one-update log-odds gain.
    student_scale: Student-t posterior scale (nu + m) / (nu + 6) after an association."""

    max_hypotheses: int = 8
    commit_threshold: float = 0.95
    release_threshold: float = 0.5
    full_count: int = 4
    miss_probability_full: float = 0.02
    birth_probability: float = 1e-12
    max_misses: int = 50
    gate: float = 100.0
    max_candidate_std: float = 1.0
    student_dof: float = 6.0
    default_sigmas: tuple[float, float] = (0.02, 0.05)
    gn_iterations: int = 3
    robust_commit: bool = True
    student_scale: bool = True

    def __post_init__(self):
        check(
            self,
            integer={
                "max_hypotheses": (1, 1000),
                "full_count": (1, 1000),
                "max_misses": (0, 1_000_000),
                "gn_iterations": (0, 1000),
            },
            interval={
                "commit_threshold": (0.5, 1.0, "[)"),
                "release_threshold": (0.0, "commit_threshold", "(]"),
                "miss_probability_full": (0.0, 1.0, "()"),
                "birth_probability": (0.0, 1.0, "()"),
                "gate": (0.0, np.inf, "(]"),
                "max_candidate_std": (0.0, np.inf, "(]"),
                "student_dof": (0.0, np.inf, "(]"),
            },
        )


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
