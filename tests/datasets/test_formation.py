"""Seed 000 Sec. VI-A as a log of measurements through the front door: static ground robots
placed by mutual bearings (one reference + the known |T_12|), the climber by P3P on its
bearings of them, everything refined in one graph (`live.event_points`)."""

import json
import shutil

import numpy as np
import pytest

from graphloc.cli import main
from graphloc.datasets import open_run
from graphloc.keys import pose_key
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.runner.team_run import team_graph


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("formation") / "run"
    assert main(["simulate", "feng-deterministic", "--out", str(out), "--seed", "0"]) == 0
    return out


def _truth(run, name):
    r = [x.name for x in run.robots].index(name)
    return r, run.groundtruth[r][1][0]


def test_the_log_holds_measurements_only(run_dir):
    manifest = json.loads((run_dir / "manifest.json").read_text())
    robots = {r["name"]: r for r in manifest["robots"]}
    assert set(robots) == {"climber", "ground1", "ground2", "ground3"}
    assert [n for n, r in robots.items() if "initial_pose" in r] == ["ground1"]
    assert not any("markers" in r for r in robots.values())
    assert robots["ground1"]["tables"]["range"] and "mutual_estimate" not in manifest["meta"]


def test_mutual_bearings_place_the_ground_robots_and_p3p_the_climber(run_dir):
    run = open_run(run_dir)
    graph = team_graph(run, GraphConfig())
    for name in ("ground2", "ground3"):
        r, truth = _truth(run, name)
        guess = graph.initial[pose_key(r, 0)]
        assert np.linalg.norm(guess.translation() - truth.translation()) < 0.1, name
    c = [x.name for x in run.robots].index("climber")
    assert len(graph.alternatives) >= 2 and graph.guessed_alternatives == graph.alternatives
    assert all(pose_key(c, 0) in v for v in graph.alternatives)
    assert graph.skips.total == 0


@pytest.mark.parametrize("verb,label", [("smooth", "batch"), ("online", "online")])
def test_smooth_and_online_estimate_every_robot(run_dir, tmp_path, verb, label):
    out = tmp_path / verb
    assert main([verb, str(run_dir), "--out", str(out), "--no-progress"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["per_robot"]["climber"][label]["ate_rmse"] < 0.06
    for name in ("ground2", "ground3"):
        assert m["per_robot"][name]["position_error_m"] < 0.05, name
        assert m["per_robot"][name]["rotation_error_deg"] < 2.0, name
    assert m["per_robot"]["ground1"]["position_error_m"] < 1e-3


def test_without_the_known_baseline_nothing_is_placed_and_that_is_counted(run_dir, tmp_path):
    """No |T_12|: the formation has no scale, so C2, C3 stay unplaced, and the climber, which
    sees only one placed robot, too; each is a counted skip, not an error."""
    manifest = json.loads((run_dir / "manifest.json").read_text())
    g1 = next(r for r in manifest["robots"] if r["name"] == "ground1")
    del g1["tables"]["range"]
    g1["sensors"] = [s for s in g1["sensors"] if s["type"] != "range"]
    copy = tmp_path / "no_range"
    shutil.copytree(run_dir, copy)
    (copy / "manifest.json").write_text(json.dumps(manifest))
    run = open_run(copy)
    graph = team_graph(run, GraphConfig())
    left_out = [e for e in graph.skips.examples if "nothing placed it" in e]
    assert sorted(e.split(":")[0] for e in left_out) == [
        "robot climber",
        "robot ground2",
        "robot ground3",
    ]
    assert graph.skips.counts["unanchored_robot"] >= 3 + 1 + 1  # their poses (+ their factors)
    result = solve(graph, "batch")
    c = [x.name for x in run.robots].index("climber")
    assert not np.isfinite(result.estimate[c]).any()
