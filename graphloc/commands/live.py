"""`graphloc live`: a running team localized as its rows arrive (`graphloc.LiveTeam`), from a log
being written (`--log-dir`) or ROS 2 topics (`--ros2`); poses published (`--publish`, `--view`),
`graphloc online`'s outputs plus live.json and live_updates.csv at the end (docs/live.md)."""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

from graphloc.commands import smooth
from graphloc.config import add_config_arguments
from graphloc.commands.common import verdict_exit
from graphloc.pipelines.team_graph.options import RunOptions
from graphloc.structured import dumps_json

HELP = "localize a running team as its rows arrive (a log being written, ROS 2 topics): poses out"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--log-dir", type=Path, help="a log directory a logger is writing (tailed)")
    src.add_argument(
        "--ros2",
        action="store_true",
        help="ROS 2 topics over Cyclone DDS: the topics of --topics FILE (graphloc import's "
        "topics file), or a log's lines (--manifest LOG); domain ROS_DOMAIN_ID",
    )
    parser.add_argument(
        "--manifest", type=Path, help="with --ros2: the log directory whose tables arrive as lines"
    )
    parser.add_argument("--out", required=True, type=Path, help="output directory")
    parser.add_argument(
        "--window", type=float, default=0.5, help="s a row may arrive late (default 0.5)"
    )
    parser.add_argument(
        "--idle", type=float, help="end this many s after the last row (not before the first)"
    )
    parser.add_argument(
        "--wait", type=float, default=60.0, help="s to wait for the log's manifest (default 60)"
    )
    parser.add_argument(
        "--view", type=int, nargs="?", const=8765, help="Foxglove live view on this port (8765)"
    )
    parser.add_argument("--publish", action="store_true", help="poses out as ROS 2 topics")
    parser.add_argument(
        "--checkpoint",
        type=Path,
        help="the live team's checkpoint (every row pushed): written every --checkpoint-every "
        "steps and at the end; when it exists, the team resumes from it",
    )
    parser.add_argument(
        "--checkpoint-every", type=int, default=500, help="steps between checkpoints (500)"
    )
    parser.add_argument("--config", type=Path, help="TOML file with any of the options below")
    add_config_arguments(parser, RunOptions)


def _source(args, opts: RunOptions):
    """(source, run directory the team opens, recorder or None)."""
    if args.log_dir is not None:
        if args.manifest is not None:
            raise ValueError("--manifest is for --ros2; --log-dir names the log itself")
        from graphloc.live.tail import LogTail

        tail = LogTail(args.log_dir)
        tail.wait_manifest(args.wait)
        return tail, args.log_dir, None
    if (opts.topics is None) == (args.manifest is None):
        raise ValueError("--ros2 takes --topics FILE (ROS messages) or --manifest LOG (log lines)")
    if args.manifest is not None:
        from graphloc.live.ros2 import Ros2LogSource

        return Ros2LogSource(args.manifest), args.manifest, None
    from graphloc.datasets.rosbag_topics import read_topics
    from graphloc.live.record import LogRecorder, check_live
    from graphloc.live.ros2 import Ros2Source
    from graphloc.live.topics import LiveTopics

    tf = read_topics(opts.topics)
    check_live(tf)
    recorder = LogRecorder(tf, Path(args.out) / "log")
    if recorder.resumed and not (args.checkpoint is not None and args.checkpoint.is_file()):
        recorder.close()
        raise ValueError(
            f"--out {args.out}: {recorder.root} holds the rows of an earlier live run; resume it "
            "with --checkpoint FILE (the one that run wrote) or give another --out"
        )
    source = Ros2Source(tf, LiveTopics(tf, scans_dir=recorder.root))
    return source, recorder.root, recorder


def run(args: argparse.Namespace) -> int:
    from graphloc.datasets import open_run
    from graphloc.live import LiveTeam
    from graphloc.live.pipeline import UPDATE_COLUMNS, LiveRun, StatusLine
    from graphloc.log_writer import write_csv as write_table_rows
    from graphloc.runner.team_run import write_run

    if args.window < 0:
        raise ValueError(f"--window must be >= 0, got {args.window}")
    if args.idle is not None and not args.idle > 0:
        raise ValueError(f"--idle must be > 0, got {args.idle}")
    opts = smooth.options(args)
    out = Path(args.out)
    with smooth.StopFlag("live") as stop:
        cpu0 = time.process_time()
        source, run_dir, recorder = _source(args, opts)
        team = LiveTeam.open(
            run_dir, replace(opts, topics=None), args.window, args.checkpoint, args.checkpoint_every
        )
        if team.resumed:
            done = " (a finished run: its outputs again)" if team.closed else ""
            print(
                f"graphloc live: resumed {args.checkpoint}: {team.resumed} rows{done}",
                file=sys.stderr,
            )
        sinks = []
        if args.publish:
            from graphloc.live.ros2 import Ros2Sink

            sinks.append(Ros2Sink(team.names, dp=getattr(source, "dp", None)))
        view = None
        if args.view is not None:
            from graphloc.live.view import LiveView

            view = LiveView(args.view)
            sinks.append(view)
            print(f"graphloc live: Foxglove view on ws://127.0.0.1:{view.port}", file=sys.stderr)
        status = StatusLine(enabled=not args.no_progress)
        live = LiveRun(team, source, sinks, status, recorder)
        if args.log_dir is not None and team.pushed:  # a resumed tail skips the rows in
            live.seen = {(r, t, row.get("line")) for r, t, row in team.pushed}
        stop.phase = "solving"
        ended = "finished" if team.closed else live.run(stop, args.idle)
        status.show(live.skipped(), force=True)
        status.close()
        stop.phase = "writing"
        result = team.finish()
        for sink in sinks:
            if hasattr(sink, "flush"):
                sink.flush()
        if recorder is not None:
            recorder.close()
        run = team.graph.run
        if (Path(run_dir) / "manifest.json").is_file():  # the ground truth as it is now
            run = replace(run, groundtruth=open_run(run_dir).groundtruth)
        cpu = time.process_time() - cpu0
        metrics = write_run(result, run, out, opts, team.graph.config, cpu, None, False, run_dir)
        summary = {
            "ended": ended,
            **status.summary(),
            "end_to_end_latency_s": live.latency_summary(),
            "skipped": {**source.skips.as_dict(), "team": team.skips.as_dict()},
            "consistent": metrics["consistent"],
        }
        (out / "live.json").write_text(dumps_json(summary, indent=1) + "\n")
        write_table_rows(out / "live_updates.csv", UPDATE_COLUMNS, live.updates)
        if view is not None:
            view.close()
        print(dumps_json({k: summary[k] for k in ("ended", "rows", "updates")}, indent=1))
    return verdict_exit("live", args, metrics["consistency"], False, opts.strict)
