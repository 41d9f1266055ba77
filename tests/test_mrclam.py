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
from benchmarks.planar_factors import integrate_unicycle
from benchmarks.planar_factors import bearing_range_2d
from graphloc.datasets import open_run
from graphloc.pipelines.report import evaluate
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.runner.team_run import team_graph

DATASET6 = Path(__file__).resolve().parents[1].parent / "shared/data/mrclam/MRCLAM_Dataset6"
HEADER = "# synthetic MRCLAM-format file\n# Time [s] ...\n"
LANDMARKS = {6: (3.0, 3.0), 7: (-3.0, 3.0), 8: (-3.0, -3.0), 9: (3.0, -3.0)}
BARCODES = {1: 5, 2: 14, 3: 41, 6: 63, 7: 81, 8: 7, 9: 70}
N_OUTLIERS = 5


def write_synthetic_mrclam(root: Path, duration=60.0, seed=0) -> dict:
    """Three robots driving smooth curves among four landmarks, odometry with a 5 % speed scale
    error and a turn-rate bias, measurements at 4 Hz. Plus bad lines: returns how many of each."""
    rng = np.random.default_rng(seed)
    root.mkdir(parents=True, exist_ok=True)
    t0 = 1000.0
    bad = {"parse": 0, "non_finite": 0, "time_backwards": 0, "field_count": 0, "unknown_barcode": 0}
    (root / "Barcodes.dat").write_text(HEADER + "".join(f"{s}\t{b}\n" for s, b in BARCODES.items()))
    (root / "Landmark_Groundtruth.dat").write_text(
        HEADER + "".join(f"{i}\t{x}\t{y}\t0.0001\t0.0001\n" for i, (x, y) in LANDMARKS.items())
    )
    t_odo = t0 + np.arange(0, duration, 0.02)
    starts = [(0.0, -1.0, 0.3), (-1.0, 1.0, -0.5), (1.0, 1.0, 2.5)]
    gts = []
    for r, start in enumerate(starts):
        v = 0.15 + 0.05 * np.sin(0.1 * (t_odo - t0) + r)
        w = 0.25 * np.sin(0.07 * (t_odo - t0) + 2 * r)
        gt = integrate_unicycle(t_odo, v, w, t_odo, start=start).poses
        gts.append(gt)
        odo = np.column_stack(
            [t_odo, 1.05 * v + rng.normal(0, 0.005, v.size), w + 0.02 + rng.normal(0, 0.02, w.size)]
        )
        lines = [f"{t:.3f}\t{a:.4f}\t{b:.4f}\n" for t, a, b in odo]
        lines.insert(100, "1000.5 0.1\n")
        bad["field_count"] += 1
        lines.insert(200, "1001.0 abc 0.1\n")
        bad["parse"] += 1
        lines.insert(300, f"{t_odo[299]:.3f} nan 0.1\n")
        bad["non_finite"] += 1
        lines.insert(400, f"{t_odo[10]:.3f} 0.1 0.1\n")  # time goes backwards
        bad["time_backwards"] += 1
        (root / f"Robot{r + 1}_Odometry.dat").write_text(HEADER + "".join(lines))
        (root / f"Robot{r + 1}_Groundtruth.dat").write_text(
            HEADER
            + "".join(f"{t:.3f}\t{x:.6f}\t{y:.6f}\t{th:.6f}\n" for t, (x, y, th) in zip(t_odo, gt))
        )
    t_meas = t0 + 1.0 + np.arange(0, duration - 2.0, 0.25)
    idx = np.searchsorted(t_odo, t_meas)
    for r in range(3):
        rows = []
        pose = gts[r][idx]
        targets = [(BARCODES[i], np.tile(xy, (idx.size, 1))) for i, xy in LANDMARKS.items()]
        targets += [(BARCODES[j + 1], gts[j][idx, :2]) for j in range(3) if j != r]
        for code, pts in targets:
            b, d = bearing_range_2d(pose, pts)
            b = b + rng.normal(0, 0.01, b.size)
            d = d + rng.normal(0, 0.03, d.size)
            rows += [(t, code, dd, bb) for t, dd, bb in zip(t_meas, d, b)]
        rows.sort(key=lambda row: row[0])
        if (
            r == 0
        ):  # gross range outliers on landmark measurements (what the robust kernel must mute)
            for i in [i for i, row in enumerate(rows) if row[1] == BARCODES[6]][
                10 : 10 + N_OUTLIERS
            ]:
                rows[i] = (rows[i][0], rows[i][1], rows[i][2] + 3.0, rows[i][3])
        lines = [f"{t:.3f}\t{c}\t{d:.3f}\t{b:.3f}\n" for t, c, d, b in rows]
        lines.insert(50, f"{rows[50][0]:.3f}\t99\t2.0\t0.1\n")  # misread barcode
        bad["unknown_barcode"] += 1
        lines.insert(60, f"{rows[60][0]:.3f}\t63\tinf\t0.1\n")
        bad["non_finite"] += 1
        (root / f"Robot{r + 1}_Measurement.dat").write_text(HEADER + "".join(lines))
    return bad


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
