"""`graphloc fuse-maps`: ground + ceiling laser map fusion (seed 004) -> fused map (PLY + PCD,
per-point robot label), top/side PNGs with trajectories, TUM trajectories, fusion_report.json.

    graphloc fuse-maps --simulate dual-robot-room [--variant furnished] [--seed 0] --out DIR
    graphloc fuse-maps --scenario DIR --out OUT            # a directory written by dual-robot-room
    graphloc fuse-maps --ground G/ --ceiling C/ (--hint "x y z qx qy qz qw" [--hint-sigma "DEG M"]
                       | --p3p setup.json) [--config fusion.toml] --out OUT

Exit codes (graphloc.exitcodes, docs/outputs.md): 0 fused; 2 bad input (one `error:` line);
3 (INCOMPLETE) the registration failed its acceptance checks -- "not fused" and why are
printed, fusion_report.json lists every candidate and check, and no fused map is written.
"""

from __future__ import annotations

import argparse

from graphloc.exitcodes import INCOMPLETE, OK

HELP = (
    "fuse ground + ceiling robot LiDAR maps "
    "(KISS-ICP, P3P + hypothesis tracking, ICP, factor graph)"
)
EXIT_NOT_FUSED = INCOMPLETE


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, help="output directory")
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
        "--hint", help="relative pose T_G0_C0: 'x y z qx qy qz qw' or 16 numbers (row-major)"
    )
    parser.add_argument(
        "--hint-sigma",
        metavar="'DEG M'",
        help="1-sigma of --hint: rotation [deg] and translation [m] "
        "(default: the config's guess_sigma)",
    )
    parser.add_argument(
        "--p3p",
        metavar="JSON",
        help="camera + LED setup with an LED pixel CSV (see graphloc.pipelines.map_fusion.inputs)",
    )
    parser.add_argument(
        "--config",
        metavar="TOML",
        help="fusion settings: [registration], [acceptance], [fusion], [odometry] "
        "tables (see graphloc.pipelines.map_fusion.config)",
    )
    parser.add_argument(
        "--rate", type=float, default=10.0, help="frame rate of --ground/--ceiling [Hz]"
    )
    parser.add_argument(
        "--variant",
        default="furnished",
        help="dual-robot-room variant (furnished, empty, rectangular, low_overlap)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--mcap", help="also write the fused map and trajectories as an MCAP file (Foxglove)"
    )
    parser.add_argument("--rerun", help="also write them as a Rerun recording (.rrd)")
    parser.add_argument("--frames", type=int, default=10)


def run(args: argparse.Namespace) -> int:
    from graphloc.pipelines.map_fusion.config import load_fusion_config
    from graphloc.experiments.fusion_demo import simulate_and_fuse
    from graphloc.pipelines.map_fusion.run import fuse_and_write, fuse_directories
    from graphloc.pipelines.map_fusion.types import FusionConfig, FusionRejected
    from graphloc.pipelines.map_fusion.report import summary_text
    from graphloc.pipelines.recording import fusion_recording, write_recordings

    config = load_fusion_config(args.config) if args.config else FusionConfig()
    if args.hint_sigma is not None and args.hint is None:
        raise ValueError("--hint-sigma needs --hint")
    try:
        if args.simulate is not None:
            if args.simulate != "dual-robot-room":
                raise ValueError(
                    "--simulate: only 'dual-robot-room' is a map fusion scenario, "
                    f"got {args.simulate!r}"
                )
            report = simulate_and_fuse(
                args.out, args.variant, args.seed, args.frames, config=config
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
            if (args.hint is None) == (args.p3p is None):
                raise ValueError(
                    "give exactly one of --hint or --p3p for the inter-robot initial guess"
                )
            report = fuse_directories(
                args.ground,
                args.ceiling,
                args.out,
                hint=args.hint,
                p3p=args.p3p,
                rate=args.rate,
                config=config,
                hint_sigma=args.hint_sigma,
            )
    except FusionRejected as exc:
        print(summary_text(exc.report))
        return EXIT_NOT_FUSED
    print(summary_text(report))
    if args.mcap or args.rerun:
        write_recordings(fusion_recording(args.out), args.mcap, args.rerun)
    return OK
