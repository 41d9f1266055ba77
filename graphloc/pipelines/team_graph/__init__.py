"""One run, one graph: the team graph's sections (motion, points, camera, candidates,
mixtures), its settings and its solve (`solve`: batch LM or online iSAM2);
the graph is built by `graphloc.live.builder.build_live` (docs/design_team_graph.md)."""

import importlib
import sys
import types

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
    "solve": "graphloc.pipelines.team_graph.solve",
    "warm_starts": "graphloc.pipelines.team_graph.solve",
}
__all__ = sorted(_API)

__getattr__, __dir__ = lazy_api(__name__, _API)


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
