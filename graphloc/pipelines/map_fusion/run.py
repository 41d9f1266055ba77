"""Entry points of the map fusion pipeline (`graphloc fuse-maps`): `fuse_and_write` (fuse ->
outputs or the "not fused" report) and `fuse_directories` (a user's own scan sequences).
"""

from __future__ import annotations

import numpy as np

from graphloc.mapping.io import POINT_BUDGET, check_scan_units, read_scan_sequence
from graphloc.pipelines.map_fusion.fusion import fuse
from graphloc.pipelines.map_fusion.inputs import parse_hint, parse_hint_sigma, read_p3p_setup
from graphloc.pipelines.map_fusion.report import write_outputs, write_rejection
from graphloc.pipelines.map_fusion.options import FusionConfig
from graphloc.pipelines.map_fusion.types import FusionInput, FusionRejected
from graphloc.textio import SkipReport


def fuse_and_write(
    inp: FusionInput, out_dir, config: FusionConfig, times, truth=None, extra=None
) -> dict:
    """fuse -> write_outputs; on FusionRejected write the "not fused" report (no map), attach
    it to the exception as `.report` and re-raise."""
    try:
        result = fuse(inp, config)
    except FusionRejected as exc:
        exc.report = write_rejection(exc, out_dir, truth=truth, extra=extra)
        raise
    return write_outputs(result, out_dir, times, truth=truth, extra=extra)["report"]


def fuse_directories(
    ground_dir,
    ceiling_dir,
    out_dir,
    hint: str | None = None,
    p3p: str | None = None,
    rate: float = 10.0,
    config: FusionConfig = FusionConfig(),
    hint_sigma: str | None = None,
) -> dict:
    """A user's two scan sequences (PCD/PLY/XYZ, file-name order, frame k of both taken together at
    k / rate seconds) + a relative pose hint (with its 1-sigma 'DEG M') or P3P observations ->
    outputs in out_dir. Raises FusionRejected (after writing the "not fused" report)."""
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be a positive frame rate [Hz], got {rate}")
    thinned = SkipReport()  # scans beyond the point budget (graphloc.mapping.io.POINT_BUDGET)
    ground, ground_files, dropped_g = read_scan_sequence(ground_dir, thinned)
    ceiling, ceiling_files, dropped_c = read_scan_sequence(ceiling_dir, thinned)
    if len(ground) != len(ceiling):
        raise ValueError(
            f"{ground_dir} has {len(ground)} scans but {ceiling_dir} has {len(ceiling)}: "
            "the pipeline needs synchronized sequences"
        )
    scales = check_scan_units(
        {"ground": (ground, ground_files), "ceiling": (ceiling, ceiling_files)}
    )
    times = np.arange(len(ground)) / float(rate)
    leds = read_p3p_setup(p3p, len(ground)) if p3p else None
    inp = FusionInput(
        times,
        ground,
        ceiling,
        leds,
        parse_hint(hint) if hint else None,
        parse_hint_sigma(hint_sigma) if hint_sigma else None,
    )
    provenance = {
        "ground": str(ground_dir),
        "ceiling": str(ceiling_dir),
        "frames": len(ground),
        "nonfinite_points_skipped": {"ground": dropped_g, "ceiling": dropped_c},
        "scans_thinned": {"point_budget": POINT_BUDGET, **thinned.as_dict()},
        "scan_scales": scales,
    }
    return fuse_and_write(inp, out_dir, config, times, extra={"input": provenance})
