"""One run, one graph: every scenario `graphloc simulate` writes runs through `graphloc smooth`
and `graphloc online`; every table of a version-2 log becomes factors (or a counted skip, or an
error naming file and field); noise comes from the manifest unless options override it."""

import json
from pathlib import Path

import gtsam
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from graphloc.cli import main
from graphloc.datasets import open_run
from graphloc.records import columns
from graphloc.manifest import write_manifest
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.runner.team_run import team_graph
from graphloc.pipelines.team_graph.rows import rows_of_matrices
from graphloc.datasets.graphloc_log import read_team_run

SMALL = {
    "feng-probabilistic": ["--max-time", "4.0"],
    "kaushik-p3p-error": ["--frames", "10"],
    "breitenmoser-target": ["--frames", "6", "--no-save-images"],
}
# ATE bars [m] for these short runs (P3P noise: seed 000 0.5 px at ~3 m, seed 004 sqrt(3) px at
# 2.5 m with a 16 mm lens, seed 001 0.1 px centroids at 0.7-3 m)
BARS = {"feng-probabilistic": 0.05, "kaushik-p3p-error": 0.25, "breitenmoser-target": 0.02}


@pytest.mark.parametrize("name", sorted(SMALL))
def test_every_scenario_through_smooth_and_online(tmp_path, name, capsys):
    run = tmp_path / "run"
    assert main(["simulate", name, "--out", str(run), "--seed", "0", *SMALL[name]]) == 0
    for mode in ("smooth", "online"):
        out = tmp_path / mode
        assert main([mode, str(run), "--out", str(out), "--no-progress"]) == 0, (
            capsys.readouterr().err
        )
        m = json.loads((out / "metrics.json").read_text())
        label = "batch" if mode == "smooth" else "online"
        climber = m["per_robot"]["climber"]
        assert climber["alignment"] == "none"
        assert climber[label]["ate_rmse"] < BARS[name], (mode, climber[label])
        assert m["decisions"]["committed"] > 0 and m["decisions"]["wrong"] == 0
        assert m["decisions"]["with_genuine_known"] == m["decisions"]["committed"]
        assert m["tables"]["markers"] > 0 and m["skipped"]["total"] == 0
        for f in (
            f"climber_{label}.tum",
            "climber_groundtruth.tum",
            "decisions.csv",
            "trajectories.png",
        ):
            assert (out / f).is_file(), f
        rows = (out / "decisions.csv").read_text().splitlines()
        assert rows[0].startswith(
            "time,robot,target,candidates,status,committed,probability,genuine,correct"
        )
        assert len(rows) - 1 == m["decisions"]["candidate_sets"]
        if mode == "online":
            assert (
                m["latency_ms"]["p95"] > 0 and climber["online_causal"]["ate_rmse"] < 2 * BARS[name]
            )


@pytest.mark.parametrize("seed", [0, 3])
def test_online_runs_a_guessed_placement_as_hypotheses(tmp_path, seed):
    """feng-deterministic seeds: nothing decides the climber's P3P candidates (three snapshots),
    so a guess places it, and from a false candidate online alone lands metres off. Online runs
    one hypothesis per candidate and keeps the one of least error, so online lands near batch."""
    run = tmp_path / "run"
    assert main(["simulate", "feng-deterministic", "--out", str(run), "--seed", str(seed)]) == 0
    graph = team_graph(open_run(run), GraphConfig())
    assert len(graph.guessed_alternatives) >= 2
    ate = {}
    for mode, label in (("smooth", "batch"), ("online", "online")):
        out = tmp_path / mode
        assert main([mode, str(run), "--out", str(out), "--no-progress"]) == 0
        m = json.loads((out / "metrics.json").read_text())
        ate[label] = m["per_robot"]["climber"][label]["ate_rmse"]
    assert ate["batch"] < 0.05 and ate["online"] < 0.15, ate


def _csv(path: Path, table: str, rows: list) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        ",".join(columns(table)) + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows)
    )


LANDMARKS = np.array([[2.0, 2.0, 0.0], [5.0, -2.0, 0.0], [8.0, 2.0, 0.0], [4.0, 3.0, 1.0]])


def bearing_log(
    root: Path, params: dict | None = None, tables: dict | None = None, offset=None
) -> Path:
    """A ground robot driving straight along x at 0.2 m/s for 10 s whose wheel odometry reads
    25 % fast, with unit bearings to four known landmarks (sensor frame = body frame, or
    `offset` = (xyz, yaw) the sensor's extrinsics)."""
    times = np.arange(0.0, 10.01, 0.5)
    _csv(root / "a/odometry.csv", "odometry", [(t, "wheels", 0.25, 0.0) for t in times])
    xyz, yaw = offset if offset is not None else ([0.0, 0.0, 0.0], 0.0)
    E = gtsam.Pose3(gtsam.Rot3.Yaw(yaw), np.asarray(xyz, float))
    rows = []
    for t in times[1:]:
        body = gtsam.Pose3(gtsam.Rot3(), np.array([0.2 * t, 0.0, 0.0]))
        for j, p in enumerate(LANDMARKS):
            d = body.compose(E).transformTo(p)
            rows.append((t, "eye", f"landmark:{j}", *np.round(d / np.linalg.norm(d), 9)))
    _csv(root / "a/bearing.csv", "bearing", rows)
    _csv(root / "a/groundtruth.csv", "groundtruth", [(t, 0.2 * t, 0.0, 0.0) for t in times])
    (root / "landmarks.csv").write_text(
        "id,x,y,z,sigma_x,sigma_y,sigma_z\n"
        + "".join(f"{j},{p[0]},{p[1]},{p[2]},0.01,0.01,0.01\n" for j, p in enumerate(LANDMARKS))
    )
    write_manifest(
        {
            "name": "bearings",
            "start_time": 0.0,
            "landmarks": {"file": "landmarks.csv"},
            "robots": [
                {
                    "name": "a",
                    "kind": "ground",
                    "initial_pose": [0, 0, 0],
                    "sensors": [
                        {"name": "wheels", "type": "odometry", "params": {"density_v": 0.1}},
                        {
                            "name": "eye",
                            "type": "bearing",
                            "extrinsics": {"xyz": list(xyz), "rpy": [0.0, 0.0, yaw]},
                            "params": params or {"bearing_sigma": 0.005},
                        },
                    ],
                    "tables": tables
                    or {
                        "odometry": "a/odometry.csv",
                        "bearing": "a/bearing.csv",
                        "groundtruth": "a/groundtruth.csv",
                    },
                }
            ],
        },
        root,
    )
    return root


def test_bearing_table_becomes_factors_not_dead_reckoning(tmp_path):
    root = bearing_log(tmp_path / "log")
    assert main(["smooth", str(root), "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    a = m["per_robot"]["a"]
    assert m["tables"]["bearing"] == 80 and m["counts"]["factors_landmark"] == 80
    assert a["batch"]["ate_rmse"] < 0.1 * a["dead_reckoning"]["ate_rmse"], a
    assert a["batch"]["ate_rmse"] < 0.01


def test_offset_bearings_share_one_sensor_pose_per_time(tmp_path):
    """An offset bearing sensor's bearings are built-in factors on one sensor pose per time,
    tied to the body pose ("sensor_tie", its own factor type); the trajectories hold the body
    poses only, batch and online as accurate as from a sensor at the body origin."""
    root = bearing_log(tmp_path / "log", offset=([0.3, -0.2, 0.5], 0.4))
    graph = team_graph(open_run(root), GraphConfig())
    assert graph.counts["sensor_poses"] == graph.counts["factors_sensor_tie"] == 20
    assert graph.counts["factors_landmark"] == 80
    for body, E in graph.sensor_poses.values():
        assert np.allclose(E.translation(), [0.3, -0.2, 0.5])
    for mode in ("smooth", "online"):
        out = tmp_path / mode
        assert main([mode, str(root), "--out", str(out), "--no-progress"]) == 0
        m = json.loads((out / "metrics.json").read_text())
        label = "batch" if mode == "smooth" else "online"
        assert m["per_robot"]["a"][label]["ate_rmse"] < 0.01, m["per_robot"]["a"]
        assert m["consistent"] and m["factors"]["sensor_tie"]["count"] == 20
        rows = (out / f"a_{label}.tum").read_text().splitlines()
        assert len(rows) == graph.counts["poses"] == m["counts"]["poses"]


def test_manifest_noise_is_used_and_options_override_it(tmp_path):
    root = bearing_log(tmp_path / "log", params={"bearing_sigma": 0.004})
    assert {p.bearing_sigma for p in read_team_run(root).points} == {0.004}
    assert {p.bearing_sigma for p in open_run(root, noise={"bearing_sigma": 0.03}).points} == {0.03}
    config = tmp_path / "c.toml"
    config.write_text("bearing_sigma = 0.03\nkeyframe_dt = 0.5\n")
    assert (
        main(
            [
                "smooth",
                str(root),
                "--out",
                str(tmp_path / "o"),
                "--config",
                str(config),
                "--keyframe-dt",
                "0.25",
                "--no-progress",
            ]
        )
        == 0
    )
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["options"]["bearing_sigma"] == 0.03 and m["options"]["keyframe_dt"] == 0.25
    assert m["config"]["keyframe_dt"] == 0.25
    config.write_text("bearing_sigmaa = 0.03\n")
    assert main(["smooth", str(root), "--out", str(tmp_path / "o2"), "--config", str(config)]) == 2


def test_unknown_or_unsupported_tables_are_errors(tmp_path, capsys):
    root = bearing_log(
        tmp_path / "log", tables={"odometry": "a/odometry.csv", "sonar": "a/sonar.csv"}
    )
    assert main(["smooth", str(root), "--out", str(tmp_path / "o")]) == 2
    assert "unknown table 'sonar'" in capsys.readouterr().err
    root = bearing_log(
        tmp_path / "log2", tables={"odometry": "a/odometry.csv", "scans": "a/scans.csv"}
    )
    data = json.loads((root / "manifest.json").read_text())
    data["robots"][0]["sensors"].append({"name": "lidar", "type": "scanner"})
    (root / "manifest.json").write_text(json.dumps(data))
    (root / "a/scans.csv").write_text("time,sensor,path\n0.0,lidar,scans/missing.ply\n")
    assert main(["validate", str(root)]) == 2  # a missing scan names table, line and field
    assert "scans.csv: line 2: field 'path'" in capsys.readouterr().err


def test_bad_rows_are_counted_with_their_reason(tmp_path):
    root = bearing_log(tmp_path / "log")
    with open(root / "a/bearing.csv", "a") as fh:
        fh.write("10.5,eye,landmark:0,3,0,0\n10.5,eye,landmark:9,1,0,0\n")
    run = read_team_run(root)
    assert run.skips.counts == {"not_unit": 1, "unknown_target": 1}
    with pytest.raises(ValueError, match=r"bearing.csv: line 82: fields 'x, y, z'"):
        read_team_run(root, on_error="raise")


def test_relative_pose3_chain_and_surface(tmp_path):
    """A climbing robot with SE(3) odometry on a ceiling (surface plane in the manifest) and
    ranges to two static beacons: the graph keeps it on the ceiling and fixes its drift."""
    root = tmp_path / "log"
    times = np.arange(0.0, 5.01, 0.5)
    true = np.column_stack([0.3 * times, 0.1 * times, np.full_like(times, 3.0)])
    rows = [
        (
            t1,
            "odo",
            t0,
            0.33 * (t1 - t0),
            0.1 * (t1 - t0),
            0.02,
            0,
            0,
            0,
            1,
            0.01,
            0.01,
            0.01,
            0.05,
            0.05,
            0.05,
        )
        for t0, t1 in zip(times[:-1], times[1:])
    ]
    _csv(root / "c/relative_pose3.csv", "relative_pose3", rows)
    beacons = {"b1": np.array([0.0, 2.0, 0.0]), "b2": np.array([2.0, -1.0, 0.0])}
    rng = [
        (t, "uwb", b, round(float(np.linalg.norm(p - x)), 6))
        for t, x in zip(times, true)
        for b, p in beacons.items()
    ]
    _csv(root / "c/range.csv", "range", rng)
    (root / "c/gt.tum").write_text(
        "".join(f"{t} {x[0]} {x[1]} {x[2]} 0 0 0 1\n" for t, x in zip(times, true))
    )
    write_manifest(
        {
            "name": "ceiling",
            "robots": [
                {
                    "name": "c",
                    "kind": "ceiling",
                    "initial_pose": [0, 0, 3, 0, 0, 0, 1],
                    "initial_sigma": [0.01, 0.01],
                    "surface": {"point": [0, 0, 3], "normal": [0, 0, -1]},
                    "sensors": [
                        {"name": "odo", "type": "odometry"},
                        {
                            "name": "uwb",
                            "type": "range",
                            "params": {"range_sigma": 0.01, "range_sigma_per_m": 0},
                        },
                    ],
                    "tables": {
                        "relative_pose3": "c/relative_pose3.csv",
                        "range": "c/range.csv",
                        "groundtruth": "c/gt.tum",
                    },
                },
                *(
                    {
                        "name": b,
                        "kind": "beacon",
                        "static": True,
                        "initial_pose": [*p, 0, 0, 0, 1],
                        "sensors": [],
                    }
                    for b, p in beacons.items()
                ),
            ],
        },
        root,
    )
    run = open_run(root)
    assert run.contributions == {"relative_pose3": 10, "range": 22, "groundtruth": 11}
    graph = team_graph(run, GraphConfig())
    assert graph.counts["factors_surface"] == 11 and graph.counts["factors_inter_robot"] == 22
    result = solve(graph, "batch")
    est = result.estimate[run.index("c")]
    assert np.abs(est[:, 2] - 3.0).max() < 0.02
    assert np.linalg.norm(est[:, :3] - true, axis=1).max() < 0.05
    dead = result.dead_reckoning[run.index("c")]
    assert np.linalg.norm(dead[-1, :3] - true[-1]) > 0.1  # the odometry alone drifts


def test_validate_reports_contributions(tmp_path, capsys):
    root = bearing_log(tmp_path / "log")
    assert main(["validate", str(root)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["rows_used"]["bearing"] == 80 and report["graph"]["factors_landmark"] == 80


def test_climber_placed_by_markers_on_a_moving_ground_robot(tmp_path):
    """Seed 004's setup as a log: a ceiling robot (no initial pose, drifting SE(3) odometry) sees
    the three LEDs of a moving ground robot (wheel odometry, known start): the candidate sets
    are decided through the ground robot's pose and place the climber; the LED pixels enter as
    projection factors on both robots' poses (each LED a point of its set, held on the ground
    robot's pose by its layout), no candidate factor counts them twice."""
    import gtsam
    from scipy.spatial.transform import Rotation

    from graphloc.datasets.feng import look_at

    rng = np.random.default_rng(4)
    root = tmp_path / "log"
    times = np.round(np.arange(0.0, 8.0, 0.1), 6)
    g_xy = np.column_stack([0.15 * times, np.zeros_like(times)])
    leds = np.array([[0.0, 0.0, 0.3], [0.6, 0.0, 0.3], [0.2, 0.45, 0.3]])
    centre = np.column_stack([g_xy, np.full_like(times, 0.3)]) + [0.27, 0.15, 0.0]
    # the climber moves on the ceiling 1-1.3 m beside the ground robot, camera on the LEDs
    c_pos = centre + np.column_stack(
        [1.0 + 0.3 * np.sin(0.6 * times), 0.4 * np.cos(0.6 * times), np.full_like(times, 2.2)]
    )
    R_wc = np.stack(
        [look_at(c[None], m, np.array([[0.0, 1.0, 0.0]]))[0] for c, m in zip(c_pos, centre)]
    )
    fx, cx, cy = 600.0, 320.0, 240.0
    rows = []
    for t, g, c, R in zip(times, g_xy, c_pos, R_wc):
        pc = (leds + [g[0], g[1], 0.0] - c) @ R
        uv = fx * pc[:, :2] / pc[:, 2:] + [cx, cy] + rng.normal(0, 0.5, (3, 2))
        rows += [(t, "cam", "g", j, round(u, 4), round(v, 4)) for j, (u, v) in enumerate(uv)]
    _csv(root / "c/markers.csv", "markers", rows)
    poses = [gtsam.Pose3(gtsam.Rot3(R), c) for R, c in zip(R_wc, c_pos)]
    steps = []
    for t0, t1, a, b in zip(times[:-1], times[1:], poses[:-1], poses[1:]):
        d = a.between(b)
        q = Rotation.from_matrix(d.rotation().matrix()).as_quat()
        steps.append(
            (
                t1,
                "odo",
                t0,
                *np.round(1.15 * d.translation(), 7),
                *np.round(q, 9),
                0.003,
                0.003,
                0.003,
                0.01,
                0.01,
                0.01,
            )
        )
    _csv(root / "c/relative_pose3.csv", "relative_pose3", steps)
    quat = Rotation.from_matrix(R_wc).as_quat()
    (root / "c/gt.tum").write_text(
        "".join(
            f"{t} {p[0]} {p[1]} {p[2]} {q[0]} {q[1]} {q[2]} {q[3]}\n"
            for t, p, q in zip(times, c_pos, quat)
        )
    )
    _csv(root / "g/odometry.csv", "odometry", [(t, "wheels", 0.15, 0.0) for t in times])
    _csv(
        root / "g/groundtruth.csv",
        "groundtruth",
        [(t, x, y, 0.0) for t, (x, y) in zip(times, g_xy)],
    )
    write_manifest(
        {
            "name": "moving-target",
            "start_time": 0.0,
            "robots": [
                {
                    "name": "c",
                    "kind": "ceiling",
                    "sensors": [
                        {"name": "odo", "type": "odometry"},
                        {
                            "name": "cam",
                            "type": "camera",
                            "params": {
                                "fx": fx,
                                "fy": fx,
                                "cx": cx,
                                "cy": cy,
                                "width": 640,
                                "height": 480,
                                "pixel_sigma": 0.5,
                            },
                        },
                    ],
                    "tables": {
                        "relative_pose3": "c/relative_pose3.csv",
                        "markers": "c/markers.csv",
                        "groundtruth": "c/gt.tum",
                    },
                },
                {
                    "name": "g",
                    "kind": "ground",
                    "initial_pose": [0, 0, 0],
                    "markers": leds.tolist(),
                    "sensors": [{"name": "wheels", "type": "odometry"}],
                    "tables": {"odometry": "g/odometry.csv", "groundtruth": "g/groundtruth.csv"},
                },
            ],
        },
        root,
    )
    for mode in ("smooth", "online"):
        assert main([mode, str(root), "--out", str(tmp_path / mode), "--no-progress"]) == 0
        m = json.loads((tmp_path / mode / "metrics.json").read_text())
        label = "batch" if mode == "smooth" else "online"
        assert m["decisions"]["committed"] > 40 and m["decisions"]["wrong"] == 0, m["decisions"]
        c = m["per_robot"]["c"]
        assert (
            c[label]["ate_rmse"] < 0.05
            and c[label]["ate_rmse"] < 0.5 * c["dead_reckoning"]["ate_rmse"]
        ), c
        assert "factors_candidate" not in m["counts"]
        sets = m["decisions"]["candidate_sets"]
        assert m["counts"]["factors_marker"] == m["counts"]["factors_marker_layout"] == 3 * sets
        assert m["consistent"], m["consistency"]


@pytest.mark.slow
def test_dual_robot_room_scans_through_smooth(tmp_path):
    """dual-robot-room's log: each robot's scans become KISS-ICP odometry steps in the graph and
    the ceiling camera's LED pixels candidate sets on the ground robot."""
    assert main(["simulate", "dual-robot-room", "--out", str(tmp_path / "run")]) == 0
    assert (
        main(["smooth", str(tmp_path / "run"), "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    )
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["tables"]["scans"] == 16 and m["tables"]["markers"] > 0
    assert m["counts"]["factors_odometry"] >= 7 and m["decisions"]["candidate_sets"] > 0
    assert m["per_robot"]["ground"]["batch"]["ate_rmse"] < 0.05
    # the ceiling robot is placed by the inter-robot scan registration (live.event_scans), the
    # P3P candidates' best guess as its hint: the ground -> ceiling transform at frame 0
    assert m["counts"]["factors_scan_match"] >= 1 and m["skipped"]["total"] == 0
    rot, trans = relative_error(tmp_path / "o", "ground", "ceiling", "batch", 0)
    assert rot < 0.1 and trans < 0.01, (rot, trans)


def relative_error(out: Path, a: str, b: str, label: str, k: int) -> tuple[float, float]:
    """Error [deg, m] of the estimated a -> b transform at pose k (TUM outputs vs ground truth)."""

    def pose(name: str) -> np.ndarray:
        row = np.loadtxt(out / name)[k]
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = Rotation.from_quat(row[4:8]).as_matrix(), row[1:4]
        return T

    est = np.linalg.inv(pose(f"{a}_{label}.tum")) @ pose(f"{b}_{label}.tum")
    true = np.linalg.inv(pose(f"{a}_groundtruth.tum")) @ pose(f"{b}_groundtruth.tum")
    D = np.linalg.inv(true) @ est
    return float(np.degrees(Rotation.from_matrix(D[:3, :3]).magnitude())), float(
        np.linalg.norm(D[:3, 3])
    )


def _climber_rms(run, result) -> float:
    r = run.index("climber")
    gt_t, gt_p = run.groundtruth[r]
    est = result.estimate[r]
    idx = [int(np.argmin(np.abs(gt_t - t))) for t in result.node_times[r]]
    truth = np.array([gt_p[i].translation() for i in idx])
    return float(np.sqrt(np.mean(np.sum((est[:, :3] - truth) ** 2, axis=1))))


def test_marker_pixels_place_a_climber_the_tracker_never_decides(tmp_path):
    """Seed 004's setting, a run whose P3P candidates (two per frame, each tens of cm off) never
    let the tracker commit: the marker pixels enter as projection factors on the LEDs' known
    positions, the tracker's guess places the climber, and batch and online both estimate it."""
    run_dir = tmp_path / "run"
    args = ["--focal-mm", "26", "--noise-variance", "3", "--seed", "2"]
    assert main(["simulate", "kaushik-p3p-error", "--out", str(run_dir), *args]) == 0
    run = open_run(run_dir)
    graph = team_graph(run, GraphConfig())
    assert graph.counts["committed_sets"] == 0
    assert graph.counts["factors_marker"] == 3 * graph.counts["candidate_sets"]
    assert graph.counts["marker_points"] == 3 and "factors_candidate" not in graph.counts
    assert len(graph.alternatives) == len(run.observations[0].candidates)
    for mode in ("batch", "online"):
        assert _climber_rms(run, solve(graph, mode)) < 0.1, mode


def test_batch_starts_from_every_candidate_of_the_first_snapshot(tmp_path):
    """Seed 000 Sec. VI-A (three snapshots, no odometry): from some P3P candidates of the
    climber's first snapshots the solve settles in a false basin (metres off); the batch solve
    starts from every one of them and keeps the least-error estimate, the genuine one."""
    from graphloc.pipelines.team_graph.passes import Pass

    run_dir = tmp_path / "run"
    assert main(["simulate", "feng-deterministic", "--out", str(run_dir), "--seed", "3"]) == 0
    run = open_run(run_dir)
    graph = team_graph(run, GraphConfig())
    assert graph.counts["committed_sets"] == 0 and len(graph.alternatives) > 1
    starts = [
        Pass(graph, "batch", {**graph.initial, **v}, False, None).run() for v in graph.alternatives
    ]
    assert max(_climber_rms(run, x) for x in starts) > 0.5
    best = solve(graph, "batch")
    least = min(x.chi2 for x in starts)
    assert best.chi2 <= least * (1 + 1e-3) and _climber_rms(run, best) < 0.05


def test_pose_rows_match_gtsam_quaternions():
    """The vectorized trajectory rows equal GTSAM's own conversion, quaternion sign included."""
    rng = np.random.default_rng(3)
    poses = [
        gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(size=3) * s), rng.normal(size=3))
        for s in rng.choice([0.01, 1.0, 3.0], size=500)
    ]
    rows = rows_of_matrices(np.array([p.matrix() for p in poses]))
    for p, row in zip(poses, rows):
        q, t = p.rotation().toQuaternion(), p.translation()
        np.testing.assert_allclose(row, [*t, q.x(), q.y(), q.z(), q.w()], atol=1e-12)
