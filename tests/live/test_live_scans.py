"""The `scans` table live: each scan through KISS-ICP as its row arrives (`event_rows.ScanFeed`,
one `mapping.odometry.ScanOdometry` per scanner), its step the loader's; the inter-robot
registration when its inputs have arrived (`live.event_scans`). A run with one scanning robot
placed by candidate sets, and dual-robot-room, are live; their live teams are `graphloc
online`."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import graphloc
from graphloc.datasets import open_run
from graphloc.datasets.scenarios import generate
from graphloc.live import LiveTeam, replay_live
from graphloc.live.builder import build_live
from graphloc.live.coverage import route, run_tables
from graphloc.live.event_rows import build_events
from graphloc.mapping.io import read_scan
from graphloc.mapping.odometry import ScanOdometry, run_odometry
from graphloc.pipelines.team_graph import GraphConfig
from graphloc.runner.team_run import team_graph
from graphloc.pipelines.team_graph.graph import factor_keys
from helpers_live import _same_estimates, _same_graph

T_CAMERA = np.eye(4)
T_CAMERA[:3, 3] = [0.1, 0.0, 0.3]
BEACON = np.eye(4)
BEACON[:3, 3] = [2.0, 1.0, 2.9]


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """dual-robot-room seed 1: the ground and ceiling robots' scans."""
    root = tmp_path_factory.mktemp("room") / "run"
    generate("dual-robot-room", root, 1)
    return root


def _tum(path) -> tuple:
    rows = np.loadtxt(path)
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(rows[:, 4:8]).as_matrix()
    poses[:, :3, 3] = rows[:, 1:4]
    return rows[:, 0], poses


@pytest.fixture(scope="module")
def scanner_log(room, tmp_path_factory):
    """One scanning robot (dual-robot-room's ground robot: its scans and ground truth) with a
    camera that sees a static beacon at every scan: two pose candidates per set, the true one
    (with a small seeded error) and one turned 40 degrees."""
    root = tmp_path_factory.mktemp("scanner") / "run"
    root.mkdir()
    shutil.copytree(room / "scans" / "ground", root / "scans" / "ground")
    shutil.copy(room / "ground" / "scans.csv", root / "scans.csv")
    shutil.copy(room / "poses_ground.tum", root / "truth.tum")
    times, poses = _tum(root / "truth.tum")
    rng = np.random.default_rng(5)
    lines = ["time,sensor,target,k,score,qw,qx,qy,qz,tx,ty,tz"]
    for t, world_T_body in zip(times, poses):
        seen = np.linalg.inv(BEACON) @ world_T_body @ T_CAMERA  # beacon_T_camera
        wrong = seen.copy()
        wrong[:3, :3] = Rotation.from_euler("z", 40, degrees=True).as_matrix() @ seen[:3, :3]
        for k, T in enumerate((seen, wrong)):
            noisy = Rotation.from_rotvec(rng.normal(0, 0.005, 3)).as_matrix() @ T[:3, :3]
            x, y, z, w = Rotation.from_matrix(noisy).as_quat()
            tx, ty, tz = T[:3, 3] + rng.normal(0, 0.01, 3)
            lines.append(f"{t},camera,beacon,{k},{1.0 - 0.5 * k},{w},{x},{y},{z},{tx},{ty},{tz}")
    (root / "candidates.csv").write_text("\n".join(lines) + "\n")
    x, y, z = poses[0][:3, 3]
    qx, qy, qz, qw = Rotation.from_matrix(poses[0][:3, :3]).as_quat()
    manifest = {
        "format": "graphloc-log",
        "version": 2,
        "name": "one-scanner",
        "robots": [
            {
                "name": "scanner",
                "planar": False,
                "initial_pose": [x, y, z, qx, qy, qz, qw],
                "sensors": [
                    {"name": "lidar", "type": "scanner"},
                    {"name": "camera", "type": "camera", "extrinsics": T_CAMERA.tolist()},
                ],
                "tables": {
                    "scans": "scans.csv",
                    "candidates": "candidates.csv",
                    "groundtruth": "truth.tum",
                },
            },
            {
                "name": "beacon",
                "static": True,
                "planar": False,
                "initial_pose": [*BEACON[:3, 3], 0.0, 0.0, 0.0, 1.0],
            },
        ],
    }
    (root / "manifest.json").write_text(json.dumps(manifest))
    return root


def test_scan_odometry_is_causal(room):
    """A scan's step depends on the scans before it only: fed one scan at a time, the steps of
    a prefix are those of the whole sequence, bit for bit, and they are `run_odometry`'s."""
    files = sorted((room / "scans" / "ceiling").glob("*.ply"))
    scans = [read_scan(f)[0] for f in files]
    whole = ScanOdometry()
    steps = [whole.add(s) for s in scans]
    assert steps[0] is None and all(s.shape == (4, 4) for s in steps[1:])
    prefix = ScanOdometry()
    for s, step in zip(scans[:4], steps[:4]):
        got = prefix.add(s)
        assert (got is None and step is None) or np.array_equal(got, step)
    np.testing.assert_allclose(
        run_odometry(scans).increments(), np.stack(steps[1:]), atol=1e-12, rtol=0
    )


def test_one_scanner_is_live_and_its_graph_is_the_whole_runs(scanner_log):
    """A run whose one scanning robot is placed by candidate sets of a static beacon: on the
    event route, nothing keeps it off; the graph built as rows arrive is the one built from the
    whole tables (what `graphloc smooth` solves)."""
    run = open_run(scanner_log)
    tables = run_tables(run)
    assert route(run, tables) == "event"
    config = GraphConfig()
    reference = build_live(run, config)  # the whole tables at once
    assert reference.factor_types.count("odometry") == len(run.scans) - 1
    emitted: list = []
    _same_graph(reference, build_events(run, config, emitted))  # `advance` after each row
    assert len(emitted[-1]) <= 1 < len(reference.steps)


def test_one_scanner_live_team_is_graphloc_online(scanner_log, tmp_path):
    """The log's rows pushed in time order: each scan through KISS-ICP as it is released, every
    step one update, the estimates and causal estimates of `run_team(..., "online")`."""
    updates = []
    team = replay_live(scanner_log, subscriber=updates.append)
    result = team.finish()
    online = graphloc.run_team(scanner_log, tmp_path / "out", "online").result
    _same_estimates(result, online)
    assert [u.step for u in updates] == list(range(len(result.graph.steps)))
    assert len(result.graph.run.scans) == len(open_run(scanner_log).scans)


def test_bad_scan_rows_are_counted_naming_robot_table_row_and_field(scanner_log, tmp_path):
    """A scans row whose file is missing, outside the run or no scan in metres: a counted skip
    naming robot, table, row and field; the scans around it still make steps."""
    root = tmp_path / "run"
    shutil.copytree(scanner_log, root)
    (root / "scans" / "tiny.xyz").write_text("0 0 0\n" * 20)
    team = LiveTeam.open(root)
    rows = [
        (0.05, "scans/missing.ply"),
        (0.06, "../outside.ply"),
        (0.07, "scans/tiny.xyz"),
    ]
    for t, path in rows:
        team.push("scanner", "scans", {"time": t, "sensor": "lidar", "path": path})
    team.push(
        "scanner", "scans", {"time": 0.2, "sensor": "lidar", "path": "scans/ground/000001.ply"}
    )
    team.finish()
    counts = team.skips.counts
    assert counts.get("bad_scan") == 2 and counts.get("path_outside_run") == 1
    examples = "\n".join(team.skips.examples)
    for n in (1, 2, 3):
        assert f"robot 'scanner', table 'scans', row {n}: field 'path'" in examples


def _cut(run, end: float):
    """The run's rows up to time `end` (relative poses by their end, scans, candidate sets)."""
    return replace(
        run,
        motions=tuple(m for m in run.motions if max(m.t0, m.t1) <= end),
        scans=tuple(s for s in run.scans if s.time <= end),
        observations=tuple(o for o in run.observations if o.time <= end),
    )


@pytest.mark.slow
def test_dual_room_registration_is_causal(room):
    """dual-robot-room: the ceiling robot, never decided by its LED pixels, is placed by the
    first registration from its stream's hypotheses that is accepted, at a set's time; the
    steps emitted before the end do not change when later rows arrive (the run cut after the
    placement emits the same steps), and the graph holds the whole-run route's factors."""
    run, config = open_run(room), GraphConfig()
    assert route(run, run_tables(run)) == "event"
    emitted = []
    graph = build_events(run, config, emitted)
    reference = team_graph(run, config)
    ceiling = run.index("ceiling")
    assert graph.anchored_from[ceiling] in {o.time for o in run.observations}
    assert graph.counts == reference.counts and graph.skips.counts == reference.skips.counts
    assert len(emitted[-1]) <= 1 < len(graph.steps)  # only the last step waits for the end
    end = graph.anchored_from[ceiling] + 0.25
    early = []
    build_events(_cut(run, end), config, early)
    before = [step for steps in early[:-1] for step in steps]  # emitted before `finish`
    assert len(before) >= 3
    for (t, group), (t_full, full) in zip(before, graph.steps):
        assert t == t_full
        assert [(factor_keys(f), kind) for f, kind in group] == [
            (factor_keys(f), kind) for f, kind in full
        ]


@pytest.mark.slow
def test_dual_room_live_team_is_graphloc_online(room, tmp_path):
    """dual-robot-room's log pushed row by row: every scan through KISS-ICP as it is released,
    the registration when its inputs are in; the estimates and causal estimates of
    `run_team(..., "online")`, which takes the same builder."""
    team = replay_live(room)
    result = team.finish()
    online = graphloc.run_team(room, tmp_path / "out", "online").result
    assert online.graph.counts.get("factors_scan_match", 0) > 0
    _same_estimates(result, online)
