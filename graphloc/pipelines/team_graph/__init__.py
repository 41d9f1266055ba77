"""One run, one graph: every table of a heterogeneous team's run (`graphloc.run.TeamRun`) as
factors on SE(3) poses, solved in batch (Levenberg-Marquardt) or online (iSAM2) through one
`graphloc.session.Session`. The function behind `graphloc smooth` and `graphloc online`.

Poses: robot r's k-th pose `pose_key(r, k)` (gtsam.Pose3, world_T_body). A robot's pose times:
- wheel odometry (planar velocities): a grid start + k * keyframe_dt, the steps integrated
  exactly along arcs (`factors.odometry.integrate_unicycle`), measurements re-expressed in the
  body frame at the grid time (only the target's motion over <= dt/2 is neglected);
- relative poses (2D or 3D tables): the tables' own time stamps;
- a static robot: one pose; any other robot: the times it observes or is observed.
A measurement joins the pose nearest its time (within dt/2 on a grid, `sync_tolerance`
otherwise) or is counted as a skip.

Factors: prior on each known initial pose; BetweenFactorPose3 per odometry / relative-pose step
(planar robots: out-of-plane directions held to `graphloc.run.PLANAR_SIGMA`); the surface a
climbing robot moves on (`factors.surface`); range-bearing (BearingRangeFactor3D /
BearingRangeFactorPose3), bearing (`factors.bearing.bearing_factor` with the sensor extrinsics,
BearingFactor3D to landmarks), range (`factors.bearing.range_factor`, RangeFactor3D); a known
landmark tied to each observation on its own (each iSAM2 update stays local): a range-bearing
as one unary KnownLandmarkFactorPose3 on the pose, a bearing or range through one prior-pinned
anchor variable (`team_graph.points`).

Candidate sets (P3P, seed 000 / 001 / 004) enter through one route: per (observer, target)
stream a `graphloc.hypotheses.HypothesisTracker` (seed 000 Sec. V's belief over the candidates,
seed 004's particle filter) decides causally, frame by frame, with the observer's odometry
between frames, each set seen in the world through the target's pose (static: known; moving:
its odometry from its initial pose, that uncertainty added to the candidates'). A decided
candidate becomes a robust factor: a prior on the observer (static target) or a between factor
observer -> target. Decisions are causal, so batch and online solve the same factors. A robot
with no known initial pose enters the online graph at its first decided set (before that
nothing anchors it).
"""

import importlib
import sys
import types

# public name -> module that defines it; loaded on first use (PEP 562), so that the verbs'
# option tree (`team_graph.options`, light) is read without GTSAM
_API = {
    "ANCHOR_BASE": "graphloc.pipelines.team_graph.config",
    "DEFAULT_LAG": "graphloc.pipelines.team_graph.options",
    "GraphConfig": "graphloc.pipelines.team_graph.config",
    "default_lag": "graphloc.pipelines.team_graph.config",
    "run_precision": "graphloc.pipelines.team_graph.config",
    "SetOutcome": "graphloc.pipelines.team_graph.decision",
    "TeamGraph": "graphloc.pipelines.team_graph.graph",
    "STEP_LOG_COLUMNS": "graphloc.pipelines.team_graph.passes",
    "TeamResult": "graphloc.pipelines.team_graph.passes",
    "solve": "graphloc.pipelines.team_graph.solve",
    "warm_start": "graphloc.pipelines.team_graph.solve",
}
__all__ = sorted(_API)


def __getattr__(name: str):
    if name in _API:
        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(__all__) | set(globals()))


class _Package(types.ModuleType):
    """`solve` names both a submodule and the function the package exports. The import system
    binds a submodule to its package's attribute when it first loads it; this keeps
    `team_graph.solve` the function (the submodule stays `sys.modules[...]`), as the package's
    eager import did."""

    @property
    def solve(self):
        return importlib.import_module("graphloc.pipelines.team_graph.solve").solve

    @solve.setter
    def solve(self, module):
        pass  # the submodule being bound on its first import


sys.modules[__name__].__class__ = _Package
