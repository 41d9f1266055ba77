"""`graphloc fuse-maps`: ground + ceiling laser map fusion (seed 004) from a simulation
(`--simulate`), a scenario directory (`--scenario`) or two scan directories (`--ground`,
`--ceiling` with `--hint` or `--p3p`); options `FuseMapsOptions`. Exit 3 (INCOMPLETE) when the
registration fails its checks: no fused map, fusion_report.json says why."""

from __future__ import annotations

import argparse
from pathlib import Path

from graphloc.config import add_config_arguments, config_from_args
from graphloc.exitcodes import INCOMPLETE, OK
from graphloc.pipelines.map_fusion.options import FuseMapsOptions

HELP = (
    "fuse ground + ceiling robot LiDAR maps "
    "(KISS-ICP, P3P + hypothesis tracking, ICP, factor graph)"
)
EXIT_NOT_FUSED = INCOMPLETE


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The inputs by hand (one source, --out); every other option is a field of
    `FuseMapsOptions`, also from `--config FILE.toml` (graphloc.pipelines.map_fusion.options)."""
    parser.add_argument("--out", required=True, type=Path, help="output directory")
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--simulate", metavar="SCENARIO", help="simulate a scenario (dual-robot-room) and fuse it"
    )
    src.add_argument(
        "--scenario", metavar="DIR", help="a dual-robot-room directory written earlier"
    )
    src.add_argument(
        "--ground", metavar="DIR", help="ground robot scans (PCD/PLY/XYZ, file-name order)"
    )
    parser.add_argument(
        "--ceiling", metavar="DIR", help="ceiling robot scans, synchronized with --ground"
    )
    parser.add_argument(
        "--config",
        type=Path,
        help="TOML file: any option below, and the pipeline's settings in [fusion], "
        "[fusion.registration], [fusion.acceptance], [fusion.odometry], ... tables",
    )
    add_config_arguments(parser, FuseMapsOptions)


def run(args: argparse.Namespace) -> int:
    from graphloc.datasets.dual_room import simulate_and_fuse
    from graphloc.pipelines.map_fusion import FusionRejected, fuse_and_write, fuse_directories
    from graphloc.pipelines.map_fusion.report import summary_text
    from graphloc.pipelines.recording import fusion_recording, write_recordings

    opts = config_from_args(FuseMapsOptions, args)
    config = opts.fusion
    try:
        if args.simulate is not None:
            if args.simulate != "dual-robot-room":
                raise ValueError(
                    "--simulate: only 'dual-robot-room' is a map fusion scenario, "
                    f"got {args.simulate!r}"
                )
            report = simulate_and_fuse(
                args.out, opts.variant, opts.seed, opts.frames, config=config
            )
        elif args.scenario is not None:
            from graphloc.datasets.dual_room import DualRoomScenario

            scenario = DualRoomScenario.load(args.scenario)
            report = fuse_and_write(
                scenario.fusion_input(),
                args.out,
                config,
                scenario.times,
                truth=scenario.T_ground0_ceiling0,
            )
        else:
            if args.ceiling is None:
                raise ValueError("--ground needs --ceiling")
            if (opts.hint is None) == (opts.p3p is None):
                raise ValueError(
                    "give exactly one of --hint or --p3p for the inter-robot initial guess"
                )
            report = fuse_directories(
                args.ground,
                args.ceiling,
                args.out,
                hint=opts.hint,
                p3p=opts.p3p,
                rate=opts.rate,
                config=config,
                hint_sigma=opts.hint_sigma,
            )
    except FusionRejected as exc:
        print(summary_text(exc.report))
        return EXIT_NOT_FUSED
    print(summary_text(report))
    if opts.mcap or opts.rerun:
        write_recordings(fusion_recording(args.out), opts.mcap, opts.rerun)
    return OK
