"""A P3P candidate set as one mixture factor: GTSAM 4.3's HybridNonlinearFactor over a discrete
mode (`candidate_mixture`) or a max-mixture (`candidate_max_mixture`), one component per
candidate (graphloc.factors.mixture.component_factors). The team graph builds its max-mixtures
from the components itself (pipelines.team_graph.mixtures); these serve tests and benchmarks."""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.mixture import (
    MaxMixture,
    component_factors,
    max_mixture_factor,
    mixture_weights,
)
from graphloc.keys import mode_key


def candidate_mixture(
    candidates: CandidateSet,
    observation: int,
    observed_key: int,
    observer_key: int | None = None,
    covariances: np.ndarray | None = None,
) -> gtsam.HybridNonlinearFactor:
    """HybridNonlinearFactor over mode_key(observation) with one component per candidate and
    component weights `mixture_weights(candidates)` (from the scores)."""
    if len(candidates) == 0:
        raise ValueError(f"candidate_mixture: observation {observation} has no candidates")
    factors = component_factors(candidates, observed_key, observer_key, covariances)
    neg_log_w = -np.log(mixture_weights(candidates))
    pairs = [
        (f, float(nlw + f.noiseModel().negLogConstant())) for f, nlw in zip(factors, neg_log_w)
    ]
    return gtsam.HybridNonlinearFactor((mode_key(observation), len(candidates)), pairs)


def candidate_max_mixture(
    candidates: CandidateSet,
    observed_key: int,
    observer_key: int | None = None,
    covariances: np.ndarray | None = None,
) -> MaxMixture:
    """Max-mixture counterpart of `candidate_mixture`: one `component_factors` factor per
    candidate, weights from the candidate scores."""
    if len(candidates) == 0:
        raise ValueError(
            f"candidate_max_mixture: candidate set (source={candidates.source!r}, "
            f"time={candidates.time}) is empty"
        )
    return max_mixture_factor(
        component_factors(candidates, observed_key, observer_key, covariances),
        mixture_weights(candidates),
    )
