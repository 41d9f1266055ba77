"""`graphloc demo`: the dual-robot-room map fusion (seed 004) end to end, `fuse-maps` options."""

from __future__ import annotations

import argparse
from pathlib import Path

from graphloc.config import add_config_arguments, config_from_args
from graphloc.exitcodes import OK
from graphloc.pipelines.map_fusion.options import FuseMapsOptions

HELP = (
    "main job: simulate dual-robot-room and fuse the ground + ceiling maps end to end "
    "(report, map, PNGs)"
)
# `fuse-maps --simulate dual-robot-room` with the same option tree, less a user's scan inputs
USER_INPUTS = ("hint", "hint_sigma", "p3p", "rate")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out", type=Path, default=Path("out/demo"), help="output directory (default out/demo)"
    )
    parser.add_argument(
        "--config", type=Path, help="TOML file: the options below and fuse-maps' [fusion] tables"
    )
    add_config_arguments(parser, FuseMapsOptions, exclude=USER_INPUTS)


def run(args: argparse.Namespace) -> int:
    from graphloc.datasets.dual_room import simulate_and_fuse
    from graphloc.pipelines.map_fusion.report import summary_text
    from graphloc.pipelines.recording import fusion_recording, write_recordings

    opts = config_from_args(FuseMapsOptions, args, exclude=USER_INPUTS)
    report = simulate_and_fuse(args.out, opts.variant, opts.seed, opts.frames, config=opts.fusion)
    print(summary_text(report))
    if opts.mcap or opts.rerun:
        write_recordings(fusion_recording(args.out), opts.mcap, opts.rerun)
    return OK
