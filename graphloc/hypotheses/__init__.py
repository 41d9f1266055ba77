"""The engine that decides among candidates: `HypothesisTracker` (tracker.py: the algorithm and
its design, seed 000 Sec. V's belief and seed 004 Sec. II-C's particle filter as a bounded bank
of Gaussian tracks), its settings and track type (config.py) and its state saved as data
(state.py)."""

from graphloc.hypotheses.config import TrackerConfig, cap_covariances
from graphloc.hypotheses.tracker import HypothesisTracker

__all__ = ["HypothesisTracker", "TrackerConfig", "cap_covariances"]
