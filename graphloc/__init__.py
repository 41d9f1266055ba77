"""graphloc: probabilistic localization of heterogeneous robot teams on GTSAM factor graphs
(docs/architecture.md, docs/api.md). The names below are the public API; they load on first
use, so `import graphloc` does not pay for GTSAM, OpenCV or Open3D."""

import importlib

__version__ = "0.1.0"

# public name -> module that defines it
_API = {
    "open_run": "graphloc.datasets",
    "TeamRun": "graphloc.run",
    "GraphConfig": "graphloc.pipelines.team_graph",
    "team_graph": "graphloc.runner.team_run",
    "solve": "graphloc.pipelines.team_graph",
    "run_team": "graphloc.runner.team_run",
    "TeamOutcome": "graphloc.runner.team_run",
    "RunOptions": "graphloc.pipelines.team_graph.options",
    "CandidateSet": "graphloc.candidates",
    "p3p_candidate_sets": "graphloc.vision.marker_poses",
    "solve_p3p": "graphloc.geometry.p3p",
    "resection_covariance": "graphloc.geometry.resection",
    "PinholeCamera": "graphloc.cameras",
    "HypothesisTracker": "graphloc.hypotheses",
    "TrackerConfig": "graphloc.hypotheses",
    "Odometry": "graphloc.seams",
    "Decision": "graphloc.seams",
    "Session": "graphloc.session",
    "SessionConfig": "graphloc.session",
    "pose_key": "graphloc.keys",
    "landmark_key": "graphloc.keys",
    "component_factors": "graphloc.factors.mixture",
    "LiveTeam": "graphloc.live",
    "LiveUpdate": "graphloc.live",
    "RobotPose": "graphloc.live",
    "NotLiveError": "graphloc.live",
    "replay_live": "graphloc.live",
}
__all__ = ["__version__", *_API]


def lazy_api(package: str, api: dict) -> tuple:
    """The `__getattr__` and `__dir__` of a package whose public names (`api`: name -> module
    that defines it) load on first use (PEP 562); graphloc's and its subpackages'."""

    def __getattr__(name: str):
        if name in api:
            return getattr(importlib.import_module(api[name]), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(api) | set(vars(importlib.import_module(package))))

    return __getattr__, __dir__


__getattr__, __dir__ = lazy_api(__name__, _API)
