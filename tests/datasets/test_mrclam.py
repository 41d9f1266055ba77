"""MRCLAM loader and the smooth / online commands: a small synthetic MRCLAM-format directory
(written here, with malformed lines, NaN, time going backwards, unknown barcodes), a truncated
slice of the real Dataset6 (default suite), and the whole Dataset6 run (slow)."""

import json
from pathlib import Path

import numpy as np
import pytest

from graphloc.cli import main
from graphloc.datasets.mrclam import MRCLAM, interpolate_pose, is_mrclam_dir
from graphloc.log_writer import write_planar_run
from graphloc.datasets import open_run
from graphloc.pipelines.report import evaluate
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.runner.team_run import team_graph
from helpers import LANDMARKS, N_OUTLIERS, write_synthetic_mrclam

DATASET6 = Path(__file__).resolve().parents[2].parent / "shared/data/mrclam/MRCLAM_Dataset6"


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    root = tmp_path_factory.mktemp("mrclam") / "MRCLAM_Synthetic"
    return root, write_synthetic_mrclam(root)


def test_loader_counts_every_skip(synthetic):
    root, bad = synthetic
    assert is_mrclam_dir(root)
    run = MRCLAM(root).load()
    assert run.robots == ("robot1", "robot2", "robot3")
    assert run.skips.counts == bad
    assert all(str(root) in e for e in run.skips.examples)
    assert set(np.unique(run.obs_landmark[run.obs_landmark >= 0])) == set(LANDMARKS)
    assert (run.obs_target_robot >= 0).sum() > 0
    np.testing.assert_allclose(
        run.initial_poses[0], interpolate_pose(run.groundtruth[0], np.array([run.start_time]))[0]
    )


def test_loader_strict_names_file_and_line(synthetic):
    root, _ = synthetic
    with pytest.raises(ValueError, match=r"Robot1_Odometry\.dat: line \d+: expected 3 fields"):
        MRCLAM(root, on_error="raise").load()


def test_loader_rejects_missing_files(tmp_path):
    with pytest.raises(FileNotFoundError):
        MRCLAM(tmp_path / "nope")
    (tmp_path / "Barcodes.dat").write_text("1 5\n")
    with pytest.raises(ValueError, match="no RobotN_Odometry"):
        MRCLAM(tmp_path).load()


def test_log_conversion_roundtrip(synthetic, tmp_path):
    root, _ = synthetic
    run = open_run(root)
    write_planar_run(MRCLAM(root).load(), tmp_path / "log")
    back = open_run(tmp_path / "log")
    assert [r.name for r in back.robots] == [r.name for r in run.robots] and back.skips.total == 0
    np.testing.assert_allclose(back.start_time, run.start_time)
    for a, b in zip(run.velocity, back.velocity):
        np.testing.assert_allclose(a, b, atol=1e-5)
    np.testing.assert_allclose(
        [p.range for p in back.points], [p.range for p in run.points], atol=1e-5
    )
    assert [(p.target, p.landmark) for p in back.points] == [
        (p.target, p.landmark) for p in run.points
    ]
    for a, b in zip(run.robots, back.robots):
        np.testing.assert_allclose(a.initial_pose.matrix(), b.initial_pose.matrix(), atol=1e-9)


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_smoothing_beats_dead_reckoning_synthetic(synthetic, mode):
    root, _ = synthetic
    run = open_run(root)
    for cfg in (
        GraphConfig(),
        GraphConfig(use_landmarks=False),
        GraphConfig(landmark_priors=False),
    ):
        result = solve(team_graph(run, cfg), mode)
        m = evaluate(result, run)
        for name, entry in m["per_robot"].items():
            assert entry[mode]["ate_rmse"] < entry["dead_reckoning"]["ate_rmse"], (name, cfg)
            if cfg.use_landmarks:
                assert entry[mode]["ate_rmse"] < 0.1
        if cfg.use_landmarks:
            assert result.downweighted["landmark"]["downweighted"] == N_OUTLIERS
            assert result.downweighted["inter_robot"]["downweighted"] == 0
        if not cfg.landmark_priors:
            est = np.array([result.landmarks[i][:2] for i in sorted(LANDMARKS)])
            truth = np.array([LANDMARKS[i] for i in sorted(LANDMARKS)])
            assert np.abs(est - truth).max() < 0.2


@pytest.mark.parametrize("verb", ["smooth", "online"])
def test_commands_on_mrclam_and_log(synthetic, tmp_path, verb):
    root, _ = synthetic
    write_planar_run(MRCLAM(root).load(), tmp_path / "log")
    for src, out in ((root, tmp_path / "out_mrclam"), (tmp_path / "log", tmp_path / "out_log")):
        assert main([verb, str(src), "--out", str(out), "--duration", "30", "--no-progress"]) == 0
        metrics = json.loads((out / "metrics.json").read_text())
        mode = "batch" if verb == "smooth" else "online"
        assert metrics["mode"] == mode and metrics["counts"]["steps"] == 121
        for name in ("robot1", "robot2", "robot3"):
            assert (out / f"{name}_{mode}.tum").is_file()
            assert (
                metrics["per_robot"][name][mode]["ate_rmse"]
                < metrics["per_robot"][name]["dead_reckoning"]["ate_rmse"]
            )
        for png in ("trajectories.png", "error_over_time.png"):
            assert (out / png).stat().st_size > 1000
        # per-frame latency is an online quantity: plotted and reported online, absent in batch
        assert (out / "latency.png").is_file() == (mode == "online")
        assert (metrics["latency_ms"] is not None) == (mode == "online")
        if mode == "online":
            assert (out / "latency.png").stat().st_size > 1000 and metrics["latency_ms"]["p95"] > 0
    assert main([verb, str(tmp_path / "missing"), "--out", str(tmp_path / "x")]) == 2


def test_commands_no_landmarks_option(synthetic, tmp_path):
    root, _ = synthetic
    assert (
        main(
            [
                "smooth",
                str(root),
                "--out",
                str(tmp_path / "o"),
                "--no-landmarks",
                "--duration",
                "20",
                "--no-progress",
            ]
        )
        == 0
    )
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["counts"].get("factors_landmark", 0) == 0 and m["counts"]["excluded_by_option"] > 0


@pytest.mark.skipif(not DATASET6.is_dir(), reason="MRCLAM Dataset6 not available")
def test_dataset6_first_two_minutes():
    run = open_run(DATASET6, duration=120.0)
    assert len(run.robots) == 5
    problem = team_graph(run, GraphConfig())
    batch, online = evaluate(solve(problem, "batch"), run), evaluate(solve(problem, "online"), run)
    for name in (r.name for r in run.robots):
        b, o = batch["per_robot"][name], online["per_robot"][name]
        assert b["batch"]["ate_rmse"] < b["dead_reckoning"]["ate_rmse"]
        assert o["online"]["ate_rmse"] < 1.2 * b["batch"]["ate_rmse"] + 0.01


@pytest.mark.slow
@pytest.mark.skipif(not DATASET6.is_dir(), reason="MRCLAM Dataset6 not available")
def test_dataset6_whole_run_bar():
    run = open_run(DATASET6)
    full = team_graph(run, GraphConfig())
    coop = team_graph(run, GraphConfig(use_landmarks=False))
    batch, online = evaluate(solve(full, "batch"), run), evaluate(solve(full, "online"), run)
    coop_batch = evaluate(solve(coop, "batch"), run)
    for name in (r.name for r in run.robots):
        b = batch["per_robot"][name]
        assert b["dead_reckoning"]["ate_rmse"] >= 5 * b["batch"]["ate_rmse"]
        assert online["per_robot"][name]["online"]["ate_rmse"] <= 1.2 * b["batch"]["ate_rmse"]
        c = coop_batch["per_robot"][name]
        assert c["batch"]["ate_rmse"] < c["dead_reckoning"]["ate_rmse"]
