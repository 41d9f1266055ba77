"""A recorded run through the live API, as if its robots were running: every row of a log
directory or an MRCLAM directory in time order, the rows of all robots merged (`run_rows`),
pushed into a `LiveTeam` (`replay`)."""

from __future__ import annotations

import heapq
from dataclasses import fields
from pathlib import Path

from graphloc.records import LANDMARK_PREFIX
from graphloc.manifest import MANIFEST
from graphloc.io import iter_records
from graphloc.live.coverage import EVENT_TABLES, LIVE_TABLES
from graphloc.live.team import LiveTeam
from graphloc.pipelines.team_graph.options import RunOptions
from graphloc.records import TABLES


def run_rows(source, options: RunOptions | None = None):
    """(robot, table, row) of every row of the run at `source` that a live team takes, in
    time order (ties: robot, then table, as `graphloc.io.iter_records` merges a log), cut
    like the loader cuts it (`RunOptions.duration`)."""
    source = Path(source)
    opts = RunOptions() if options is None else options
    if (source / MANIFEST).is_file():
        return _log_rows(source, opts.duration)
    return _mrclam_rows(source, opts.duration)


def replay(team: LiveTeam, rows) -> None:
    """Push `rows` ((robot, table, row) each) into `team`, in their order."""
    for robot, table, row in rows:
        team.push(robot, table, row)


def _log_rows(root: Path, duration):
    end = None
    if duration is not None:
        from graphloc.datasets import open_run

        end = open_run(root).start_time + duration
    table_of = {cls: name for name, cls in TABLES.items()}
    live = LIVE_TABLES + EVENT_TABLES
    tables = [t for t in TABLES if t in live and t != "groundtruth"]  # the log's order
    for rec in iter_records(root, tables=tables, on_error="skip"):
        if end is not None and rec.time > end:
            continue
        row = {f.name: getattr(rec, f.name) for f in fields(rec) if f.name not in ("robot", "line")}
        yield rec.robot, table_of[type(rec)], row


def _mrclam_rows(root: Path, duration):
    """An MRCLAM directory's rows as `write_planar_run` writes them (sensors "wheels" and
    "camera"), as numbers."""
    from graphloc.datasets.mrclam import MRCLAM

    run = MRCLAM(root, duration=duration).load()
    names = run.robots

    def odometry(r):
        for t, v, w in run.odometry[r]:
            row = {"time": float(t), "sensor": "wheels", "v": float(v), "omega": float(w)}
            yield names[r], "odometry", row

    def observations():
        for t, r, target, lm, rng, b in zip(
            run.obs_time,
            run.obs_robot,
            run.obs_target_robot,
            run.obs_landmark,
            run.obs_range,
            run.obs_bearing,
        ):
            seen = names[target] if target >= 0 else f"{LANDMARK_PREFIX}{lm}"
            row = {"time": float(t), "sensor": "camera", "target": seen}
            yield names[r], "range_bearing", {**row, "range": float(rng), "bearing": float(b)}

    streams = [odometry(r) for r in range(len(names))] + [observations()]
    return heapq.merge(*streams, key=lambda e: e[2]["time"])
