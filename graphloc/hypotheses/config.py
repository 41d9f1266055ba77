"""The settings of the HypothesisTracker (graphloc.hypotheses.tracker), `TrackerConfig`; light
(no GTSAM, no NumPy): the command line's options are derived from it. Its track type, fit score
and covariance cap are in `graphloc.hypotheses.track`."""

from __future__ import annotations

import math
from dataclasses import dataclass

from graphloc.config import check


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
                "gate": (0.0, math.inf, "(]"),
                "max_candidate_std": (0.0, math.inf, "(]"),
                "student_dof": (0.0, math.inf, "(]"),
            },
        )
