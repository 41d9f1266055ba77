"""The seam between front-ends and engines: every plausible pose of one observation, scored."""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np


@dataclass(frozen=True)
class CandidateSet:
    """K candidate poses from one observation.

    R: (K,3,3) rotations, t: (K,3) translations -- the pose `T_ref_obj` of the observed frame
    in the reference frame (for P3P: camera in world, `R_wc`, `t_wc`).
    scores: (K,) non-negative quality (higher is better; e.g. exp(-reprojection^2/2 sigma^2)).
    time: timestamp [s]; observer / observed: robot names; source: which front-end made it.
    covariance: (K,6,6) first-order covariance of each pose (GTSAM Pose3 tangent order, right
    perturbation), e.g. `graphloc.geometry.resection.resection_covariance`; None = unknown
    (the engines then use their default sigmas).
    """

    R: np.ndarray
    t: np.ndarray
    scores: np.ndarray
    time: float = 0.0
    observer: str = ""
    observed: str = ""
    source: str = ""
    meta: dict = field(default_factory=dict, compare=False)
    covariance: np.ndarray | None = field(default=None, compare=False)

    def __post_init__(self):
        R = np.asarray(self.R, dtype=float)
        t = np.asarray(self.t, dtype=float)
        s = np.asarray(self.scores, dtype=float)
        if R.ndim != 3 or R.shape[1:] != (3, 3):
            raise ValueError(f"CandidateSet.R must be (K,3,3), got {R.shape}")
        if t.shape != (R.shape[0], 3):
            raise ValueError(f"CandidateSet.t must be ({R.shape[0]},3), got {t.shape}")
        if s.shape != (R.shape[0],):
            raise ValueError(f"CandidateSet.scores must be ({R.shape[0]},), got {s.shape}")
        if not (np.isfinite(R).all() and np.isfinite(t).all() and np.isfinite(s).all()):
            raise ValueError("CandidateSet contains NaN/inf")
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "scores", s)
        if self.covariance is not None:
            cov = np.asarray(self.covariance, dtype=float)
            if cov.shape != (R.shape[0], 6, 6):
                raise ValueError(
                    f"CandidateSet.covariance must be ({R.shape[0]},6,6), got {cov.shape}"
                )
            object.__setattr__(self, "covariance", cov)

    def __len__(self) -> int:
        return self.R.shape[0]

    def poses(self) -> list[gtsam.Pose3]:
        return [gtsam.Pose3(gtsam.Rot3(R), t) for R, t in zip(self.R, self.t)]

    def weights(self) -> np.ndarray:
        """Scores normalized to sum 1 (uniform if all scores are zero)."""
        total = self.scores.sum()
        if len(self) == 0:
            return self.scores.copy()
        return self.scores / total if total > 0 else np.full(len(self), 1.0 / len(self))
