"""Ground + ceiling laser map fusion (seed 004, Kaushik et al.) as one factor graph -- the
pipeline of `graphloc fuse-maps` and `graphloc demo`. Small modules:

    config     FusionConfig (light: the option tree reads it)
    types      the inputs (scans + LED observations or a hint), GuessResult,
               FusionResult, FusionRejected ("not fused")
    led_guess  LED pixels -> P3P candidate sets (`graphloc.vision.marker_poses`) ->
               HypothesisTracker -> the inter-robot guess and its covariance; the candidate
               sets -> max-mixture factors (`graphloc.factors.mixture`)
    fusion     `fuse`: KISS-ICP odometry, robust inter-robot registration, one graph, the map
    inputs     a user's hint, hint sigma and P3P setup, parsed and checked
    run        `fuse_and_write` (outputs or the "not fused" report), `fuse_directories`
    report     fused map (PLY / PCD), PNGs, TUM trajectories, fusion_report.json
    options    `FuseMapsOptions`: the options and `--config` schema of `fuse-maps` / `demo`

The registration and scan algorithms it calls are the library `graphloc.mapping`.
"""

import importlib

# public name -> module that defines it; loaded on first use (PEP 562), so that the verbs'
# option tree (`map_fusion.options`, light) is read without Open3D, KISS-ICP or GTSAM
_API = {
    "FusionConfig": "graphloc.pipelines.map_fusion.config",
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
