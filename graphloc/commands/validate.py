"""`graphloc validate RUN`: read and build a run as `smooth` / `online` do and print what each
table contributes, without solving; exit 2 when the run is rejected."""

from __future__ import annotations

import argparse
from pathlib import Path

from graphloc.exitcodes import OK
from graphloc.config import add_config_arguments, config_from_args
from graphloc.pipelines.team_graph.options import OUTPUTS, SOLVER, RunOptions
from graphloc.structured import dumps_json

HELP = "check a run (log or MRCLAM dir): what every table contributes to the graph, what is skipped"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "run",
        help="graphloc log directory (manifest.json), MRCLAM dataset directory, bag, or a "
        "pose-graph file (City10000 / g2o)",
    )
    parser.add_argument("--config", type=Path, help="TOML file with any of the options below")
    add_config_arguments(parser, RunOptions, exclude=SKIPPED)


# the options of `smooth` / `online` that only the solve and its outputs use
SKIPPED = SOLVER + OUTPUTS


def run(args: argparse.Namespace) -> int:
    from graphloc.commands import pose_graph_run

    opts = config_from_args(RunOptions, args, exclude=SKIPPED)
    if pose_graph_run.is_pose_graph_file(args.run):  # City10000 / g2o
        graph = pose_graph_run.read_file(args.run, opts.pose_graph())
        report = pose_graph_run.summary(graph)
        print(dumps_json(report, indent=1, default=str))
        if report["unreachable_edges"]:  # smooth / online would stop there: bad input
            raise ValueError(f"{args.run}: {report['first_unreachable']}")
        return OK
    pose_graph_run.reject_options(opts.pose_graph(), args.run)
    from graphloc.datasets import open_run
    from graphloc.runner.team_run import landmark_map, team_graph

    config = opts.graph_config()
    team = open_run(args.run, duration=opts.duration, noise=opts.noise(), source=opts.source())
    graph = team_graph(team, config)  # the graph smooth / online solve
    robots = {}
    for r, robot in enumerate(team.robots):
        robots[robot.name] = {
            "kind": robot.kind,
            "planar": robot.planar,
            "static": robot.static,
            "initial_pose": robot.initial_pose is not None,
            "surface": robot.surface is not None,
            "markers": 0 if robot.markers is None else len(robot.markers),
            "poses": int(len(graph.node_times[r])),
            "groundtruth": team.groundtruth[r] is not None,
        }
    print(
        dumps_json(
            {
                "run": team.name,
                "robots": robots,
                "rows_used": team.contributions,
                "graph": graph.counts,
                "skipped": graph.skips.as_dict(),
                "notes": team.notes.as_dict(),
                "landmark_map": landmark_map(team, config),
            },
            indent=1,
            default=str,
        )
    )
    return OK
