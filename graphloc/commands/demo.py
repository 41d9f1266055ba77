"""`graphloc demo`: the README's main job on the bundled default scenario -- the furnished
`dual-robot-room` end to end (seed 004 pipeline): simulate the two robots' LiDAR scans and the
ceiling camera's LED pixels -> P3P candidates -> HypothesisTracker over the ceiling robot's motion
-> ICP from that guess -> joint factor graph (Session) -> fused labelled map, PNG renderings,
TUM trajectories and fusion_report.json in --out."""

from __future__ import annotations

import argparse

from graphloc.exitcodes import OK

HELP = (
    "main job: simulate dual-robot-room and fuse the ground + ceiling maps end to end "
    "(report, map, PNGs)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out/demo", help="output directory (default out/demo)")
    parser.add_argument("--seed", type=int, default=0, help="scenario seed (default 0)")


def run(args: argparse.Namespace) -> int:
    from graphloc.pipelines.map_fusion.report import summary_text
    from graphloc.experiments.fusion_demo import run_demo

    report = run_demo(args.out, args.seed)
    print(summary_text(report))
    return OK
