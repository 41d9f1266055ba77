"""Ground + ceiling laser map fusion (seed 004, Kaushik et al.) as one factor graph -- the
pipeline of `graphloc fuse-maps` and `graphloc demo` (its modules: docs/architecture.md); the
registration and scan algorithms it calls are the library `graphloc.mapping`.
"""

from graphloc import lazy_api

# public name -> module that defines it; loaded on first use (PEP 562), so that the verbs'
# option tree (`map_fusion.options`, light) is read without Open3D, KISS-ICP or GTSAM
_API = {
    "FusionConfig": "graphloc.pipelines.map_fusion.options",
    "FusionInput": "graphloc.pipelines.map_fusion.types",
    "FusionRejected": "graphloc.pipelines.map_fusion.types",
    "FusionResult": "graphloc.pipelines.map_fusion.types",
    "GuessResult": "graphloc.pipelines.map_fusion.types",
    "LedObservations": "graphloc.pipelines.map_fusion.types",
    "fuse": "graphloc.pipelines.map_fusion.fusion",
    "fuse_and_write": "graphloc.pipelines.map_fusion.run",
    "fuse_directories": "graphloc.pipelines.map_fusion.run",
}
__all__ = sorted(_API)

__getattr__, __dir__ = lazy_api(__name__, _API)
