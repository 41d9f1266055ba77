"""The settings of the HypothesisTracker (graphloc.hypotheses.tracker), `TrackerConfig`; light
(no GTSAM, no NumPy): the command line's options are derived from it. Its track type, fit score
and covariance cap are in `graphloc.hypotheses.track`."""

from __future__ import annotations

from graphloc.config_schema import config_dataclass, setting


@config_dataclass
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

    max_hypotheses: int = setting(8, ge=1, le=1000)
    commit_threshold: float = setting(0.95, ge=0.5, lt=1.0)
    release_threshold: float = setting(0.5, gt=0.0)
    full_count: int = setting(4, ge=1, le=1000)
    miss_probability_full: float = setting(0.02, gt=0.0, lt=1.0)
    birth_probability: float = setting(1e-12, gt=0.0, lt=1.0)
    max_misses: int = setting(50, ge=0, le=1_000_000)
    gate: float = setting(100.0, gt=0.0, allow_inf_nan=True)
    max_candidate_std: float = setting(1.0, gt=0.0, allow_inf_nan=True)
    student_dof: float = setting(6.0, gt=0.0, allow_inf_nan=True)
    default_sigmas: tuple[float, float] = (0.02, 0.05)
    gn_iterations: int = setting(3, ge=0, le=1000)
    robust_commit: bool = True
    student_scale: bool = True

    def __post_init__(self):
        if not 0.0 < self.release_threshold <= self.commit_threshold:
            raise ValueError(
                "TrackerConfig.release_threshold must be in (0, commit_threshold = "
                f"{self.commit_threshold:g}], got {self.release_threshold}"
            )
