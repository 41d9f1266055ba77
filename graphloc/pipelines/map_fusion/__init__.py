"""Ground + ceiling laser map fusion (seed 004, Kaushik et al.) as one factor graph -- the
pipeline of `graphloc fuse-maps` and `graphloc demo`. Small modules:

    types      FusionConfig, the inputs (scans + LED observations or a hint), GuessResult,
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

from graphloc.pipelines.map_fusion.fusion import fuse
from graphloc.pipelines.map_fusion.run import fuse_and_write, fuse_directories
from graphloc.pipelines.map_fusion.types import (
    FusionConfig,
    FusionInput,
    FusionRejected,
    FusionResult,
    GuessResult,
    LedObservations,
)

__all__ = [
    "FusionConfig",
    "FusionInput",
    "FusionRejected",
    "FusionResult",
    "GuessResult",
    "LedObservations",
    "fuse",
    "fuse_and_write",
    "fuse_directories",
]
