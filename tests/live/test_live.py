"""The live API (`graphloc.live`): rows pushed in time order give the steps, factors and initial
values of the whole-run builder and the estimates of `graphloc online`; rows shuffled within the
window the same; late and bad rows counted skips; runs that need sections not live yet refused
at open, naming them."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import graphloc
from graphloc.datasets import open_run
from graphloc.factors.odometry import VelocityNoise
from benchmarks.planar_factors import integrate_unicycle
from graphloc.live import LiveTeam, NotLiveError, replay, replay_live, run_rows
from graphloc.live.arc import ArcIntegrator
from graphloc.live.builder import build_live
from graphloc.pipelines.team_graph import GraphConfig
from helpers_live import _fed_in_chunks, _same_estimates, _same_graph

DATASET6 = Path(__file__).resolve().parents[2].parent / "shared/data/mrclam/MRCLAM_Dataset6"
needs_dataset6 = pytest.mark.skipif(not DATASET6.is_dir(), reason="MRCLAM Dataset6 not present")


def test_arc_integrator_is_integrate_unicycle_bit_for_bit():
    """Stamps and rows arriving in random chunks (duplicate sample times, samples before the
    first stamp, stamps on samples) give the whole-run integration's poses, steps and
    covariances exactly."""
    rng = np.random.default_rng(3)
    t = np.sort(np.concatenate([rng.uniform(-1.0, 30.0, 400), [5.0, 5.0, 7.5]]))
    rows = np.column_stack([t, rng.normal(0.3, 0.2, len(t)), rng.normal(0.0, 0.5, len(t))])
    stamps = 0.25 * np.arange(117)
    noise = VelocityNoise(density_v=0.03, density_w=0.07)
    ref = integrate_unicycle(rows[:, 0], rows[:, 1], rows[:, 2], stamps, noise)
    n = 0
    arc = ArcIntegrator(lambda: rows[:n], noise)
    parts, i = [], 0
    while i < len(stamps):
        j = min(len(stamps), i + int(rng.integers(1, 6)))
        n = int(np.searchsorted(rows[:, 0], stamps[j - 1], "right")) + int(rng.integers(0, 3))
        parts.append(arc.advance(stamps[i:j]))
        i = j
    poses, deltas, covs = (np.concatenate(p) for p in zip(*parts))
    assert np.array_equal(poses, ref.poses)
    assert np.array_equal(deltas, ref.deltas)
    assert np.array_equal(covs, ref.covariances)


@pytest.mark.parametrize(
    "config",
    [
        GraphConfig(),
        GraphConfig(landmark_priors=False),  # SLAM: landmark guesses from the first pose
        GraphConfig(anchor_known_landmarks=False, keyframe_dt=0.1),
    ],
    ids=["known", "slam", "shared-landmarks"],
)
def test_live_graph_of_whole_tables_is_the_graph_of_rows_one_by_one(planar_log, config):
    """The graph `graphloc smooth` solves (each table fed whole) is the graph of the rows pushed
    one at a time in time order, `advance` after each (what `graphloc live` builds)."""
    run = open_run(planar_log)
    _same_graph(_fed_in_chunks(run, config, None), build_live(run, config))


@needs_dataset6
def test_live_graph_of_whole_tables_is_the_graph_of_rows_one_by_one_on_dataset6():
    run = open_run(DATASET6, duration=30.0)
    config = GraphConfig()
    _same_graph(_fed_in_chunks(run, config, None), build_live(run, config))


@pytest.mark.parametrize("seed", [0, 1])
def test_the_graph_does_not_depend_on_how_rows_are_split(planar_log, seed):
    """Rows pushed in chunks give `build_live`'s whole-table feed's graph: the batched release
    of waiting measurements is the same rule."""
    run = open_run(planar_log)
    config = GraphConfig(keyframe_dt=0.1)
    graph = build_live(run, config)
    _same_graph(graph, _fed_in_chunks(run, config, seed))


@needs_dataset6
def test_the_graph_does_not_depend_on_how_rows_are_split_on_dataset6():
    run = open_run(DATASET6, duration=60.0)
    config = GraphConfig()
    _same_graph(build_live(run, config), _fed_in_chunks(run, config, 2))


def test_live_team_is_graphloc_online(planar_log, tmp_path):
    """A log directory's rows pushed in time order: every step one update, the estimates and
    causal estimates of `run_team(..., "online")`."""
    updates = []
    team = replay_live(planar_log, subscriber=updates.append)
    result = team.finish()
    online = graphloc.run_team(planar_log, tmp_path / "out", "online").result
    _same_estimates(result, online)
    assert [u.step for u in updates] == list(range(len(result.graph.steps)))
    assert all(np.isfinite(u.latency_s) and u.latency_s >= 0 for u in updates)
    last = team.latest(team.names[0])
    assert last.index == len(result.node_times[0]) - 1
    assert last.covariance.shape == (6, 6)
    assert np.all(np.linalg.eigvalsh(last.covariance) > 0)
    np.testing.assert_allclose(
        np.r_[last.pose.translation()], result.estimate[0][-1, :3], atol=1e-9
    )


@needs_dataset6
def test_live_team_is_graphloc_online_on_dataset6(tmp_path):
    options = graphloc.RunOptions(duration=60.0)
    result = replay_live(DATASET6, options).finish()
    online = graphloc.run_team(DATASET6, tmp_path / "out", "online", options).result
    _same_estimates(result, online)


@pytest.mark.slow
@needs_dataset6
def test_live_team_is_graphloc_online_on_full_dataset6(tmp_path):
    result = replay_live(DATASET6).finish()
    online = graphloc.run_team(DATASET6, tmp_path / "out", "online").result
    _same_estimates(result, online)


def test_shuffled_within_the_window_is_time_order(mrclam_dir):
    """Rows arriving out of order by less than the window are put back in time order: the
    result is that of the rows in time order, and nothing is counted late."""
    rows = list(run_rows(mrclam_dir))
    ordered = replay_live(mrclam_dir, window=0.5)
    times = np.array([row["time"] for _, _, row in rows])
    jitter = np.random.default_rng(7).uniform(0.0, 0.4, len(rows))
    shuffled = [rows[i] for i in np.argsort(times + jitter, kind="stable")]
    assert shuffled != rows
    team = LiveTeam.open(mrclam_dir, window=0.5)
    replay(team, shuffled)
    _same_estimates(team.finish(), ordered.finish(), tol=0.0)
    assert "late_row" not in team.skips.counts


def test_late_row_beyond_the_window_is_a_counted_skip(mrclam_dir):
    """A row older than the window's release front is counted (`late_row`, naming robot and
    table) and left out: the result is that of the rows without it."""
    rows = list(run_rows(mrclam_dir))
    k = next(i for i, (_, table, _) in enumerate(rows) if table == "range_bearing" and i > 50)
    late = rows.pop(k)
    team = LiveTeam.open(mrclam_dir, window=0.5)
    replay(team, rows[: k + 40])
    assert rows[k + 39][2]["time"] - late[2]["time"] > 0.5
    team.push(*late)
    assert team.skips.counts.get("late_row") == 1
    message = next(e for e in team.skips.examples if "released" in e)
    assert message.startswith(f"robot {late[0]!r}, table 'range_bearing', row {k + 41}: time ")
    replay(team, rows[k + 40 :])
    without = LiveTeam.open(mrclam_dir, window=0.5)
    replay(without, rows)
    _same_estimates(team.finish(), without.finish(), tol=0.0)


def test_bad_rows_are_counted_skips_naming_robot_table_and_field(mrclam_dir):
    team = LiveTeam.open(mrclam_dir)
    robot = team.names[0]
    t = team.setup.start_time + 0.01
    team.push(robot, "odometry", {"time": t, "sensor": "wheels", "v": "fast", "omega": 0.0})
    team.push(robot, "odometry", {"time": t, "sensor": "wheels", "v": 0.1, "omega": float("nan")})
    team.push(robot, "odometry", {"time": t, "sensor": "lidar", "v": 0.1, "omega": 0.0})
    row = {"time": t, "sensor": "camera", "target": "landmark:999", "range": 1.0, "bearing": 0.0}
    team.push(robot, "range_bearing", row)
    team.push(robot, "range_bearing", {**row, "target": team.names[1], "range": -1.0})
    team.push(robot, "odometry", {"time": t, "sensor": "wheels", "v": 0.1})
    counts = team.skips.counts
    for reason in (
        "parse",
        "non_finite",
        "unknown_sensor",
        "unknown_target",
        "non_positive_range",
        "missing_field",
    ):
        assert counts.get(reason) == 1, reason
    examples = "\n".join(team.skips.examples)
    assert f"robot {robot!r}, table 'odometry', row 1: field 'v'" in examples
    assert f"robot {robot!r}, table 'range_bearing', row 5: field 'range'" in examples
    with pytest.raises(ValueError, match="unknown robot"):
        team.push("nobody", "odometry", {})
    with pytest.raises(NotLiveError, match="markers"):
        team.push(robot, "markers", {})


def test_a_robot_nothing_can_place_is_left_out_live(tmp_path):
    """feng-deterministic whose climber logs no bearings: nothing can place it (no candidate
    sets, circles or bearings). No refusal: the live team takes the run, leaves the climber out
    (a counted `unanchored_robot` naming it, no pose) and places the static robots, as
    `graphloc online` does."""
    import json

    from graphloc.datasets.scenarios import generate

    generate("feng-deterministic", tmp_path / "run", 1)
    path = tmp_path / "run" / "manifest.json"
    manifest = json.loads(path.read_text())
    del manifest["robots"][0]["tables"]["bearing"]  # the climber's
    path.write_text(json.dumps(manifest))
    team = replay_live(tmp_path / "run")
    result = team.finish()
    assert set(team.skips.counts) == {"unanchored_robot"}
    assert "robot climber: nothing placed it" in "\n".join(team.skips.examples)
    assert team.latest("climber") is None and np.isnan(result.estimate[0]).all()
    assert all(np.isfinite(e).all() for e in result.estimate[1:])
    online = graphloc.run_team(tmp_path / "run", tmp_path / "out", "online")
    _same_estimates(result, online.result)
    assert online.metrics["skipped"]["counts"] == team.skips.counts


def test_no_rows_yet_means_no_pose(mrclam_dir):
    team = LiveTeam.open(mrclam_dir)
    assert team.latest(team.names[0]) is None
    robot = team.names[0]
    start = team.setup.start_time
    team.push(robot, "odometry", {"time": start - 0.1, "sensor": "wheels", "v": 0.0, "omega": 0.0})
    assert team.latest(robot) is None  # the other robot's odometry may still reach the start


def test_live_options_replace_the_noise(mrclam_dir):
    """`RunOptions` noise reaches the rows' handlers as it reaches the loader's."""
    options = graphloc.RunOptions(range_sigma=0.2, bearing_sigma=0.05)
    team = replay_live(mrclam_dir, options)
    run = open_run(mrclam_dir, noise=options.noise())
    live_points = team.finish().graph.run.points
    assert [(m.range_sigma, m.bearing_sigma) for m in live_points] == [
        (m.range_sigma, m.bearing_sigma) for m in run.points
    ]


def test_the_api_doc_block_runs(mrclam_dir, capsys):
    text = (Path(__file__).resolve().parents[2] / "docs/api.md").read_text(encoding="utf-8")
    section = text.split("## Live: rows pushed as a team runs")[1].split("\n## ")[0]
    block = section.split("```python\n")[1].split("```")[0]
    scope = {"run_dir": mrclam_dir}
    exec(compile(block, "docs/api.md", "exec"), scope)
    assert scope["result"].steps_done == len(scope["result"].graph.steps) == len(scope["seen"])
    assert scope["pose"].covariance.shape == (6, 6)
    assert "updates;" in capsys.readouterr().out


def test_a_restarted_team_resumes_from_its_checkpoint(mrclam_dir, tmp_path):
    """A team killed after a checkpoint and opened again with it replays the rows the file
    holds (the same graph, checked by its fingerprint); pushing the rest gives the result of a
    team never stopped: nothing before the checkpoint is lost."""
    rows = list(run_rows(mrclam_dir))
    path = tmp_path / "live.checkpoint"
    first = LiveTeam.open(mrclam_dir, checkpoint=path, checkpoint_every=10)
    replay(first, rows[: len(rows) // 2])
    assert path.is_file() and first.solver.done >= 10
    del first  # killed: the rows after its last checkpoint are lost with it
    second = LiveTeam.open(mrclam_dir, checkpoint=path, checkpoint_every=10)
    assert 0 < second.resumed <= len(rows) // 2
    assert second.solver.done % 10 == 0
    replay(second, rows[second.resumed :])
    _same_estimates(second.finish(), replay_live(mrclam_dir).finish(), tol=0.0)
    finished = LiveTeam.open(mrclam_dir, checkpoint=path)  # written by finish(): finished
    _same_estimates(finished.finish(), second.finish(), tol=0.0)
    with pytest.raises(ValueError, match="after finish"):
        finished.push(*rows[0])


def test_a_checkpoint_of_another_run_or_option_is_refused(mrclam_dir, tmp_path):
    rows = list(run_rows(mrclam_dir))
    path = tmp_path / "live.checkpoint"
    team = LiveTeam.open(mrclam_dir, checkpoint=path, checkpoint_every=5)
    replay(team, rows[:200])
    with pytest.raises(ValueError, match="another run or configuration"):
        LiveTeam.open(mrclam_dir, graphloc.RunOptions(keyframe_dt=0.1), checkpoint=path)
    with pytest.raises(ValueError, match="window"):
        LiveTeam.open(mrclam_dir, window=1.0, checkpoint=path)
    path.write_text("not a checkpoint\n")
    with pytest.raises(ValueError, match=str(path)):
        LiveTeam.open(mrclam_dir, checkpoint=path)


def _bearing_and_range_log(planar_log: Path) -> Path:
    """The planar log with its range-bearing rows also as `bearing` rows (3D unit directions,
    from a sensor offset from the body origin: sensor poses) and `range` rows (an offset
    sensor), the first robot on a surface, and no start_time (the rows give it)."""
    from helpers import edit_manifest

    def edit(data):
        data.pop("start_time")
        for i, robot in enumerate(data["robots"]):
            robot["sensors"] += [
                {"name": "eye", "type": "bearing", "extrinsics": [0.1, 0.05, 0.3]},
                {"name": "ranger", "type": "range", "extrinsics": [-0.1, 0.0, 0.0]},
            ]
            robot["tables"]["bearing"] = f"{robot['name']}/bearing.csv"
            robot["tables"]["range"] = f"{robot['name']}/range.csv"
            if i == 0:
                robot["surface"] = {"point": [0, 0, 0], "normal": [0, 0, 1], "attitude_sigma": 0.01}
            lines = (planar_log / robot["tables"]["range_bearing"]).read_text().splitlines()
            bearing, ranges = ["time,sensor,target,x,y,z"], ["time,sensor,target,range"]
            for line in lines[1:]:
                t, _, target, rng, b = line.split(",")
                c, s = np.cos(float(b)), np.sin(float(b))
                bearing.append(f"{t},eye,{target},{c:.9f},{s:.9f},0.0")
                ranges.append(f"{t},ranger,{target},{float(rng) + 0.05:.6f}")
            (planar_log / robot["tables"]["bearing"]).write_text("\n".join(bearing) + "\n")
            (planar_log / robot["tables"]["range"]).write_text("\n".join(ranges) + "\n")

    edit_manifest(planar_log, edit)
    return planar_log


@pytest.mark.parametrize("unknown_landmarks", [False, True], ids=["known", "slam"])
def test_bearings_ranges_surfaces_and_a_start_from_the_rows(
    planar_log, tmp_path, unknown_landmarks
):
    log = _bearing_and_range_log(planar_log)
    options = graphloc.RunOptions(unknown_landmarks=unknown_landmarks)
    run = open_run(log)
    config = replace(options.graph_config(), lag=0.0)
    graph = build_live(run, config)
    assert graph.counts["sensor_poses"] > 0 and graph.counts.get("factors_surface", 0) > 0
    _same_graph(_fed_in_chunks(run, config, None), graph)
    result = replay_live(log, options).finish()
    _same_estimates(result, graphloc.run_team(log, tmp_path / "out", "online", options).result)


@pytest.mark.slow
@needs_dataset6
@pytest.mark.parametrize("landmark_priors", [True, False], ids=["known", "slam"])
def test_live_graph_of_whole_tables_is_the_graph_of_chunks_on_full_dataset6(landmark_priors):
    run = open_run(DATASET6)
    config = GraphConfig(landmark_priors=landmark_priors)
    _same_graph(_fed_in_chunks(run, config, 0), build_live(run, config))


def test_a_manifest_without_tables_takes_pushed_rows(planar_log, tmp_path):
    """A live team opened from a manifest whose robots list no tables (the rows are pushed,
    not logged) solves the rows of the log they came from as the log itself."""
    import shutil

    from helpers import edit_manifest

    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(planar_log / "manifest.json", bare / "manifest.json")
    shutil.copy(planar_log / "landmarks.csv", bare / "landmarks.csv")

    def no_tables(data):
        for robot in data["robots"]:
            robot["tables"] = {}

    edit_manifest(bare, no_tables)
    team = LiveTeam.open(bare)
    replay(team, run_rows(planar_log))
    _same_estimates(team.finish(), replay_live(planar_log).finish(), tol=0.0)


@needs_dataset6
def test_a_step_is_not_held_for_the_next_grid_pose():
    """Window 0: a step at T is solved once the rows up to T + dt/2 are in and its
    measurements' nearest poses are certain -- a measurement at T < t < T + dt/2 is nearest to
    T before the pose at T + dt exists -- so a step with range-bearing rows just after it
    mostly does not wait for odometry at its next grid pose (some wait for other robots' rows
    or a tie's later pose)."""
    options = graphloc.RunOptions(duration=30.0)
    team = LiveTeam.open(DATASET6, options, window=0.0)
    dt = team.graph.config.keyframe_dt
    trigger = {}  # step time -> time of the row whose push solved it
    now = [None]
    team.subscribe(lambda u: trigger.setdefault(u.time, now[0]), covariance=False)
    after = set()  # steps with a range-bearing row in (T, T + dt/2), not at the tie
    for robot, table, row in run_rows(DATASET6, options):
        now[0] = float(row["time"])
        team.push(robot, table, row)
        if table == "range_bearing":
            k = (now[0] - team.builder.start) / dt
            if 0.05 < k - np.floor(k) < 0.45:
                after.add(round(team.builder.start + np.floor(k) * dt, 6))
    team.finish()
    held = [t for t, at in trigger.items() if at is not None and round(t, 6) in after]
    early = [t for t in held if trigger[t] < t + dt]  # solved before its next grid pose
    assert len(held) > 20
    assert len(early) > len(held) / 2  # waiting for the pose at T + dt: hardly any early
