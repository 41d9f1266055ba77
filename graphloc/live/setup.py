"""What a live team knows before its first row (`live_setup`): the robots, sensors, landmarks
and start time of a log directory's manifest.json or of an MRCLAM directory, the graph
configuration of the `RunOptions`, and the manifest its rows are checked against."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from graphloc.manifest import MANIFEST, read_manifest
from graphloc.textio import SkipReport
from graphloc.io import read_landmarks
from graphloc.manifest import Manifest, Robot, Sensor, check_noise_params
from graphloc.pipelines.team_graph.config import GraphConfig
from graphloc.pipelines.team_graph.options import RunOptions
from graphloc.run import NOISE_DEFAULTS, TeamRun


@dataclass(frozen=True)
class LiveSetup:
    """What a live team knows before its first row: the `TeamRun` without rows, the manifest rows
    are checked against, the handlers' noise defaults, the known landmark ids (None: SLAM), the
    graph's config (the lag set), the start time (None: the rows tell) and each robot's tables
    (`coverage.route`)."""

    run: TeamRun
    manifest: Manifest
    noise: dict
    landmark_ids: set | None
    config: GraphConfig
    start_time: float | None
    tables: dict | None = None


def live_setup(source: Path, options: RunOptions | None = None) -> LiveSetup:
    """The setup of the run at `source` (a log directory or an MRCLAM directory); raises
    `NotLiveError` naming every table and robot that needs a section not live yet."""
    from graphloc.datasets.mrclam import is_mrclam_dir

    opts = RunOptions() if options is None else options
    noise = opts.noise()
    check_noise_params(noise, "option (command line or --config)")
    if (source / MANIFEST).is_file():
        run, manifest, defaults, ids, start, tables = _log_setup(source, noise)
    elif is_mrclam_dir(source):
        run, manifest, defaults, ids, start, tables = _mrclam_setup(source, noise, opts.duration)
    else:
        raise FileNotFoundError(
            f"{source}: a live team opens a log directory ({MANIFEST}) or an MRCLAM directory"
        )
    return LiveSetup(run, manifest, defaults, ids, opts.graph_config(run), start, tables)


def empty_run(run: TeamRun) -> TeamRun:
    """`run` without its rows (what a live team starts from)."""
    return replace(
        run,
        velocity=tuple(np.zeros((0, 3)) for _ in run.robots),
        motions=(),
        points=(),
        observations=(),
        features=(),
        scans=(),
    )


def _log_setup(root: Path, noise: dict):
    from graphloc.datasets.log_rows import team_robot

    manifest = read_manifest(root)
    for r in manifest.robots:
        for s in r.sensors:
            s.params.update(noise)
    robots = tuple(team_robot(r) for r in manifest.robots)
    ids, xyz, sig = read_landmarks(manifest)
    known = manifest.landmarks_file is not None
    run = TeamRun(
        name=manifest.name,
        robots=robots,
        start_time=np.nan if manifest.start_time is None else float(manifest.start_time),
        velocity=tuple(np.zeros((0, 3)) for _ in robots),
        motions=(),
        points=(),
        observations=(),
        groundtruth=tuple(None for _ in robots),
        landmark_ids=ids,
        landmark_xyz=xyz,
        landmark_sigma=sig,
        landmarks_known=known,
        skips=SkipReport(),
        meta=dict(manifest.meta),
    )
    # a robot that lists no tables takes the live ones (its rows are pushed, not logged)
    tables = {
        r.name: tuple(r.tables) or (() if r.static else ("odometry",)) for r in manifest.robots
    }
    landmark_ids = set(ids.tolist()) if known else None
    return run, manifest, dict(NOISE_DEFAULTS), landmark_ids, manifest.start_time, tables


def _mrclam_setup(root: Path, noise: dict, duration):
    """An MRCLAM directory's team as `open_run` loads it (its robots' initial poses from the
    ground truth at the start), rows as `write_planar_run` names them: `odometry` (sensor
    "wheels"), `range_bearing` (sensor "camera", targets robot names and landmark:<id>)."""
    from graphloc.datasets.mrclam import MRCLAM
    from graphloc.run import team_run_from_planar

    run = team_run_from_planar(MRCLAM(root, duration=duration).load(), noise)
    eye = np.eye(4)
    robots = tuple(
        Robot(
            r.name,
            "ground",
            (Sensor("wheels", "odometry", eye), Sensor("camera", "range_bearing", eye)),
        )
        for r in run.robots
    )
    manifest = Manifest(root, run.name, robots, None, run.start_time, dict(run.meta))
    tables = {r.name: ("odometry", "range_bearing") for r in run.robots}
    landmark_ids = set(np.asarray(run.landmark_ids).tolist())
    defaults = {**NOISE_DEFAULTS, **noise}
    return empty_run(run), manifest, defaults, landmark_ids, run.start_time, tables
