"""A camera without an initial pose on the event route (`graphloc.live.event_camera`): its
feature tracks and circle sets wait for the placement that its candidate sets give it, then
enter (the tracks' landmark priors and the teammate's placement through its pose, at the step
that placed it); a camera nothing places leaves its rows as counted skips naming robot and
table (tests/live/test_live_camera.py)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import graphloc
from graphloc.datasets import open_run
from graphloc.datasets.scenarios import generate
from graphloc.live import replay_live
from graphloc.live.coverage import route, run_tables
from graphloc.live.event_rows import build_events
from graphloc.pipelines.report import evaluate
from graphloc.pipelines.team_graph import GraphConfig, solve
from helpers_live import _same_estimates, _same_graph


@pytest.fixture(scope="module")
def feng_features(tmp_path_factory):
    """feng-probabilistic (a climber without an initial pose placed by its marker sets of a
    static target) with and without a `features` table on the climber."""
    root = tmp_path_factory.mktemp("feng")
    generate("feng-probabilistic", root / "plain", 0)
    shutil.copytree(root / "plain", root / "features")
    add_features(root / "features")
    return root


@pytest.fixture(scope="module")
def crawler_beacon(tmp_path_factory):
    """crawler-pair seed 1 with a static beacon the camera sees as logged candidate sets, the
    camera without its initial pose: the beacon's decided sets place it."""
    root = tmp_path_factory.mktemp("crawler") / "run"
    generate("crawler-pair", root, 1)
    add_beacon(root)
    manifest = json.loads((root / "manifest.json").read_text())
    del manifest["robots"][0]["initial_pose"]
    (root / "manifest.json").write_text(json.dumps(manifest))
    return root


def _ate(result, run) -> dict:
    """Batch ATE [m] per robot with an estimate (`report.evaluate`)."""
    per_robot = evaluate(result, run)["per_robot"]
    return {name: v["batch"]["ate_rmse"] for name, v in per_robot.items() if "batch" in v}


def _one_row_at_a_time(run):
    """`build_events` with `advance` after every row (the live order) and with every row in
    before the first `advance`: the graph must not depend on when the rows came."""
    steps: list = []
    return build_events(run, GraphConfig(), steps), build_events(run, GraphConfig()), steps


def test_feature_tracks_of_a_camera_placed_by_its_marker_sets(feng_features, tmp_path):
    """The climber (no initial pose) is placed at its first decided marker set; its feature
    pixels are factors as they come, held by the online pass with its other factors, and each
    track's landmark guess and point prior wait for that placement and join its step. Every
    pixel and every track's prior is in the graph; the live team is `graphloc online`; the
    tracks make the batch estimate better than the log without them."""
    run = open_run(feng_features / "features")
    tables = run_tables(run)
    assert route(run, tables) == "event"
    live, whole, emitted = _one_row_at_a_time(run)
    _same_graph(whole, live)
    assert sum(map(len, emitted)) == len(live.steps) and len(emitted[-1]) < len(live.steps)
    counts, placed = live.counts, live.anchored_from[0]
    assert counts["factors_projection"] == len(run.features) > 0
    assert counts["factors_feature_prior"] == counts["feature_tracks"] > 0
    first_pixel = min(f.time for f in run.features)
    assert first_pixel < placed < np.inf
    prior_steps = [t for t, group in live.steps for _, kind in group if kind == "feature_prior"]
    assert min(prior_steps) == placed  # the tracks seen before the placement join its step

    updates = []
    team = replay_live(feng_features / "features", subscriber=updates.append)
    result = team.finish()
    online = graphloc.run_team(feng_features / "features", tmp_path / "online", "online")
    _same_estimates(result, online.result)
    assert min(u.time for u in updates if "climber" in u.poses) == placed
    assert not team.skips.counts

    ours = _ate(solve(live, "batch"), run)["climber"]
    plain = open_run(feng_features / "plain")
    assert ours < _ate(solve(build_events(plain, GraphConfig()), "batch"), plain)["climber"]


def test_circle_sets_of_a_camera_placed_by_candidate_sets(crawler_beacon, tmp_path):
    """The camera (no initial pose) is placed by its decided candidate sets of the beacon; its
    circle sets of the teammate wait for that, then go through their max-mixture stream in
    order and place the teammate through the camera's pose, held as long as the camera is.
    Both are localized to within the teammate base's radius."""
    run = open_run(crawler_beacon)
    tables = run_tables(run)
    assert route(run, tables) == "event"
    live, whole, _ = _one_row_at_a_time(run)
    _same_graph(whole, live)
    circles = [o for o in run.observations if o.candidates.source == "circle"]
    assert sum(d.robot == 0 and d.target == 1 for d in live.decisions) == len(circles) > 0
    first_circle = min(o.time for o in circles)
    assert first_circle < live.anchored_from[0] == live.anchored_from[1] < np.inf
    assert not live.skips.counts

    updates = []
    team = replay_live(crawler_beacon, subscriber=updates.append)
    result = team.finish()
    online = graphloc.run_team(crawler_beacon, tmp_path / "online", "online")
    _same_estimates(result, online.result)
    for name in ("camera", "teammate"):
        assert min(u.time for u in updates if name in u.poses) == live.anchored_from[0]

    ours = _ate(solve(live, "batch"), run)
    assert max(ours["teammate"], ours["camera"]) < run.robots[1].base_radius


def add_features(root: Path, robot: str = "climber", n: int = 30, seed: int = 0) -> None:
    """Give `robot` of the log at `root` (its camera sensor 'camera' at the body, its truth a
    TUM file) a `features` table: `n` world points near the ground projected through its true
    poses at their times with 0.5 px noise, one track per point, the pixels in the image."""
    rng = np.random.default_rng(seed)
    manifest = json.loads((root / "manifest.json").read_text())
    spec = next(r for r in manifest["robots"] if r["name"] == robot)
    cam = next(s for s in spec["sensors"] if s["name"] == "camera")["params"]
    truth = np.loadtxt(root / spec["tables"]["groundtruth"])  # t x y z qx qy qz qw
    points = np.column_stack([rng.uniform(-0.5, 3.5, (n, 2)), rng.uniform(0.0, 0.5, n)])
    rows = ["time,sensor,track,u,v"]
    for t, *pose in truth.tolist():
        R, pose = Rotation.from_quat(pose[3:]).as_matrix(), np.array(pose)
        local = (points - pose[:3]) @ R  # R^T (p - t): the points in the camera frame
        z = local[:, 2]
        u = cam["fx"] * local[:, 0] / z + cam["cx"] + rng.normal(0.0, 0.5, n)
        v = cam["fy"] * local[:, 1] / z + cam["cy"] + rng.normal(0.0, 0.5, n)
        seen = (z > 0.1) & (u >= 0) & (u < cam["width"]) & (v >= 0) & (v < cam["height"])
        rows += [
            f"{t!r},camera,{j},{float(u[j])!r},{float(v[j])!r}"
            for j in np.flatnonzero(seen).tolist()
        ]
    (root / robot / "features.csv").write_text("\n".join(rows) + "\n")
    spec["tables"]["features"] = f"{robot}/features.csv"
    (root / "manifest.json").write_text(json.dumps(manifest, indent=2))


def add_beacon(root: Path, robot: str = "camera", sensor: str = "cam", seed: int = 0) -> None:
    """Give the log at `root` a static robot 'beacon' with a known pose and `robot` a
    `candidates` table of it at each of its truth's times: two candidates of the beacon's pose
    in the sensor frame (the body's: no extrinsics) -- the true one with 5 mrad / 5 mm noise,
    score 0.7, and one turned 0.6 rad and shifted 10 cm, score 0.3."""
    import gtsam

    rng = np.random.default_rng(seed)
    manifest = json.loads((root / "manifest.json").read_text())
    spec = next(r for r in manifest["robots"] if r["name"] == robot)
    truth = np.loadtxt(root / spec["tables"]["groundtruth"])  # t x y z qx qy qz qw
    beacon = gtsam.Pose3(gtsam.Rot3.Rz(0.3), np.array([0.2, -0.1, 1.0]))
    wrong = gtsam.Pose3(gtsam.Rot3.Ry(0.6), np.array([0.1, 0.0, 0.0]))
    rows = ["time,sensor,target,k,score,qw,qx,qy,qz,tx,ty,tz"]
    for t, x, y, z, qx, qy, qz, qw in truth.tolist():
        body = gtsam.Pose3(gtsam.Rot3.Quaternion(qw, qx, qy, qz), np.array([x, y, z]))
        true = beacon.between(body)  # target_T_sensor
        noisy = true.compose(gtsam.Pose3.Expmap(rng.normal(0.0, 0.005, 6)))
        for k, (pose, score) in enumerate([(noisy, 0.7), (true.compose(wrong), 0.3)]):
            q, p = pose.rotation().toQuaternion(), pose.translation()
            values = [q.w(), q.x(), q.y(), q.z(), *p.tolist()]
            rows.append(f"{t!r},{sensor},beacon,{k},{score}," + ",".join(map(repr, values)))
    (root / f"{robot}_candidates.csv").write_text("\n".join(rows) + "\n")
    spec["tables"]["candidates"] = f"{robot}_candidates.csv"
    pose = [*beacon.translation().tolist(), *beacon.rotation().toQuaternion().coeffs().tolist()]
    manifest["robots"].append(
        {
            "name": "beacon",
            "kind": "ground",
            "static": True,
            "initial_pose": pose,
            "sensors": [],
            "tables": {},
        }
    )
    (root / "manifest.json").write_text(json.dumps(manifest, indent=2))
