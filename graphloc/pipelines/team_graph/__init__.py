"""One run, one graph: the team graph's sections (motion, points, camera, candidates,
mixtures), its settings and its solve (`solve`: batch LM or online iSAM2);
the graph is built by `graphloc.live.builder.build_live` (docs/design_team_graph.md)."""

from graphloc import lazy_api

# public name -> module that defines it; loaded on first use (PEP 562), so that the verbs'
# option tree (`team_graph.options`, light) is read without GTSAM
_API = {
    "ANCHOR_BASE": "graphloc.pipelines.team_graph.config",
    "DEFAULT_LAG": "graphloc.pipelines.team_graph.options",
    "GraphConfig": "graphloc.pipelines.team_graph.config",
    "default_lag": "graphloc.pipelines.team_graph.config",
    "run_precision": "graphloc.pipelines.team_graph.config",
    "SetOutcome": "graphloc.pipelines.team_graph.candidates",
    "TeamGraph": "graphloc.pipelines.team_graph.graph",
    "STEP_LOG_COLUMNS": "graphloc.pipelines.team_graph.passes",
    "TeamResult": "graphloc.pipelines.team_graph.passes",
    "solve": "graphloc.pipelines.team_graph.solver",
    "warm_starts": "graphloc.pipelines.team_graph.solver",
}
__all__ = sorted(_API)

__getattr__, __dir__ = lazy_api(__name__, _API)
