"""The engine that decides among candidates: `HypothesisTracker` (tracker.py: the algorithm and
its design, seed 000 Sec. V's belief and seed 004 Sec. II-C's particle filter as a bounded bank
of Gaussian tracks), its settings (config.py, light: the command line's options derive from
it), its track type, fit score and covariance cap (track.py), its state saved as data
(state.py) and its per-child window update (window.py: GTSAM's Gauss-Newton on the 2-pose
windows, in batched NumPy over se3.py's Pose3 maps).

The names below load on first use (PEP 562), so importing `TrackerConfig` does not load GTSAM."""

from graphloc import lazy_api

# public name -> module that defines it
_API = {
    "HypothesisTracker": "graphloc.hypotheses.tracker",
    "TrackerConfig": "graphloc.hypotheses.config",
    "cap_covariances": "graphloc.hypotheses.track",
}
__all__ = list(_API)

__getattr__, __dir__ = lazy_api(__name__, _API)
