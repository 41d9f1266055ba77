"""Ground + ceiling laser map fusion (seed 004, Kaushik et al.) as one factor graph -- the
pipeline of `graphloc fuse-maps` and `graphloc demo` (its modules: docs/architecture.md); the
registration and scan algorithms it calls are the library `graphloc.mapping`.
"""

import importlib

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


def __getattr__(name: str):
    if name in _API:
        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(__all__) | set(globals()))
