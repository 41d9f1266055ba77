"""The live API on team logs graphloc did not write (tests/foreign/live_generator.py, written from
docs/log_format.md and docs/api.md alone): pushed rows give `graphloc online`'s estimates, the
estimates sit within their reported covariances of the generator's truth, rows in the window in
any order (equal times too) give the in-order result, late and bad rows are counted skips or
errors naming robot and table, a raising subscriber leaves the team whole, checkpoints resume."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import gtsam
import numpy as np
import pytest
from scipy.stats import chi2

import graphloc
from graphloc.checkpoint import read_checkpoint_file
from graphloc.live import LiveTeam, NotLiveError, run_rows

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "foreign"))
from live_generator import Scenario, generate, write_log  # noqa: E402

SMALL = {
    "loop": Scenario("loop", robots=3, duration=8.0, seed=1),
    "corridor-slam": Scenario(
        "corridor", robots=2, duration=8.0, slam=True, seed=2, odometry_hz=(100.0, 10.0)
    ),
    "far": Scenario("far", robots=4, duration=8.0, seed=3, density_v=0.05, bearing_sigma=0.02),
    "slope": Scenario("slope", robots=3, duration=8.0, seed=4, measurement_hz=4.0),
}


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """name -> (TeamLog, its directory, graphloc online's result on it)."""
    out = {}
    root = tmp_path_factory.mktemp("live_foreign")
    for name, sc in SMALL.items():
        log = generate(sc)
        run_dir = write_log(log, root / name)
        online = graphloc.run_team(run_dir, root / f"{name}_online", "online").result
        out[name] = (log, run_dir, online)
    return out


def _pushed(run_dir, pushes, window=0.5, **kw) -> LiveTeam:
    team = LiveTeam.open(run_dir, window=window, **kw)
    for robot, table, row in pushes:
        team.push(robot, table, row)
    return team


def _same(result, reference, tol=1e-9) -> None:
    assert len(result.estimate) == len(reference.estimate)
    assert sum(len(e) for e in result.estimate) > 10 * len(result.estimate)
    for name in ("estimate", "causal"):
        for a, b in zip(getattr(result, name), getattr(reference, name)):
            assert a.shape == b.shape and len(a) >= 1
            assert np.array_equal(np.isnan(a), np.isnan(b))
            assert np.nanmax(np.abs(a - b)) <= tol


@pytest.mark.parametrize("name", list(SMALL))
def test_live_in_time_order_is_graphloc_online(logs, name):
    log, run_dir, online = logs[name]
    team = _pushed(run_dir, log.pushes())
    _same(team.finish(), online)
    assert team.rows == len(log.rows)
    assert not set(team.skips.counts) - {"landmark_without_position"}  # SLAM: range-only


@pytest.mark.parametrize("name", ["loop", "corridor-slam"])
def test_equal_times_in_any_arrival_order_give_graphloc_online(logs, name):
    """Rows of equal time (the generator gives robots common odometry and measurement times)
    arriving in another order -- robots and tables reversed -- give online's estimates: the
    window puts ties in the log's order (robot, then table)."""
    log, run_dir, online = logs[name]
    ties = [(t, r) for t, r, *_ in log.rows]
    assert len({t for t, _ in ties}) < len(set(ties))  # equal times across robots
    rows = sorted(log.rows, key=lambda e: (e[0], -e[1], -e[2], e[3]))
    team = _pushed(run_dir, [e[4:] for e in rows])
    _same(team.finish(), online)


@pytest.mark.parametrize("name", ["loop", "far"])
def test_rows_shuffled_within_the_window_give_the_in_order_result(logs, name):
    log, run_dir, online = logs[name]
    rng = np.random.default_rng(7)
    arrival = np.array([e[0] for e in log.rows]) + rng.uniform(0.0, 0.45, len(log.rows))
    rows = [log.rows[i][4:] for i in np.argsort(arrival, kind="stable")]
    assert rows != [e[4:] for e in log.rows]
    team = _pushed(run_dir, rows, window=0.5)
    assert "late_row" not in team.skips.counts
    _same(team.finish(), online)


def _nees(log, team) -> np.ndarray:
    """Normalized estimation errors of every pose a subscriber got (the estimate and the
    marginal covariance LiveTeam reported, against the generator's truth at the pose's time)."""
    out = []

    def seen(update):
        for name, p in update.poses.items():
            truth = gtsam.Pose3(log.robots[log.names.index(name)].pose(p.time))
            e = p.pose.localCoordinates(truth)
            out.append(float(e @ np.linalg.solve(p.covariance, e)))

    team.subscribe(seen)
    return out


def _consistent(nees) -> bool:
    """6-dof normalized errors of a consistent estimator: their mean at most 6 (a planar
    robot's roll, pitch and height are held near zero, so ~3 is typical) and at most 1 % of
    them beyond the 99.9 % quantile."""
    nees = np.asarray(nees)
    return nees.mean() <= 6.0 and (nees > chi2.ppf(0.999, 6)).mean() <= 0.01


@pytest.mark.parametrize("name", list(SMALL))
def test_estimates_lie_within_their_covariances_of_the_truth(logs, name):
    log, run_dir, _ = logs[name]
    team = LiveTeam.open(run_dir, options=graphloc.RunOptions(keyframe_dt=0.1))
    nees = _nees(log, team)
    for row in log.pushes():
        team.push(*row)
    team.finish()
    assert len(nees) >= 50 * len(log.robots)
    assert _consistent(nees), (np.mean(nees), np.max(nees))
    # the check can fail: the same estimates against a truth 3 sigma of position off
    sigma = max(np.sqrt(team.latest(robot).covariance[3, 3]) for robot in log.names)
    offset = np.array([3.0 * sigma, 0.0, 0.0])
    for rb in log.robots:
        rb.origin = rb.origin.copy()
        rb.origin[:3, 3] += offset
    try:
        team2 = LiveTeam.open(run_dir, options=graphloc.RunOptions(keyframe_dt=0.1))
        nees2 = _nees(log, team2)
        for row in log.pushes():
            team2.push(*row)
        team2.finish()
        assert not _consistent(nees2)
    finally:
        for rb in log.robots:
            rb.origin[:3, 3] -= offset


def test_rows_beyond_the_window_are_counted_late_and_left_out(logs):
    log, run_dir, _ = logs["loop"]
    rows = log.pushes()
    late = [i for i in range(200, len(rows) - 200, 97) if rows[i][1] != "odometry"][:5]
    delayed = [rows[i] for i in late]
    on_time = [row for i, row in enumerate(rows) if i not in set(late)]
    # each late row arrives 150 rows after its place (several seconds: beyond 0.5 s)
    order = list(on_time)
    for row in delayed:
        at = next(j for j, r in enumerate(order) if r[2]["time"] > row[2]["time"] + 1.0)
        order.insert(at, row)
    team = _pushed(run_dir, order)
    assert team.skips.counts.get("late_row") == len(delayed)
    examples = [e for e in team.skips.examples if "released" in e]
    assert examples[0].startswith(f"robot {delayed[0][0]!r}, table {delayed[0][1]!r}, row ")
    _same(team.finish(), _pushed(run_dir, on_time).finish(), tol=0.0)


BAD = [
    # (what, mutation of a range row, reason, field named)
    ("nan", {"range": float("nan")}, "non_finite", "range"),
    ("text", {"range": "far"}, "parse", "range"),
    ("text time", {"time": "noon"}, "parse", "time"),
    ("unknown sensor", {"sensor": "sonar"}, "unknown_sensor", "sensor"),
    ("wrong sensor type", {"sensor": "cam"}, "sensor_type", "sensor"),
    ("unknown robot target", {"target": "rover9"}, "unknown_target", "target"),
    ("unknown landmark", {"target": "landmark:999"}, "unknown_target", "target"),
    ("self", {"target": "rover0"}, "self_observation", "target"),
    ("negative range", {"range": -2.0}, "non_positive_range", "range"),
    ("implausible time", {"time": 1e12}, "implausible", "time"),
    ("extra column", {"rnage": 3.0}, "unknown_field", "rnage"),
    ("bytes number", {"range": b"3.0"}, "parse", "range"),
    ("bytes text", {"sensor": b"uwb"}, "parse", "sensor"),
]


def test_bad_rows_are_counted_skips_naming_robot_table_and_field(logs):
    """Each bad row pushed mid-run is one counted skip whose message names robot, table, row
    and field; the team's result is that of the good rows."""
    log, run_dir, online = logs["loop"]
    rows = log.pushes()
    k = next(i for i in range(len(rows) // 2, len(rows)) if rows[i][:2] == ("rover0", "range"))
    team = LiveTeam.open(run_dir)
    for row in rows[:k]:
        team.push(*row)
    base = dict(rows[k][2])
    n = team.rows
    for what, change, reason, field in BAD:
        team.push("rover0", "range", {**base, **change})
        n += 1
        assert team.skips.counts.get(reason, 0) >= 1, what
        message = [e for e in team.skips.examples if f"row {n}:" in e]
        assert message and message[0].startswith(
            f"robot 'rover0', table 'range', row {n}: field {field!r}"
        ), (what, message)
    # time going backwards far beyond the window: late
    team.push("rover0", "range", {**base, "time": base["time"] - 100.0})
    assert team.skips.counts["late_row"] == 1
    missing = dict(base)
    del missing["target"]
    team.push("rover0", "range", missing)
    assert team.skips.counts["missing_field"] == 1
    assert sum(team.skips.counts.values()) == len(BAD) + 2
    # pushes no row can be: errors naming robot and table, the team untouched
    for robot, table, row, error, text in [
        ("rover9", "range", base, ValueError, "unknown robot 'rover9'"),
        ("rover0", "lidar", base, ValueError, "unknown table 'lidar'"),
        ("rover0", "features", base, NotLiveError, "not live in this team"),
        ("rover0", "scans", base, NotLiveError, "not live in this team"),
        ("rover0", "markers", base, NotLiveError, "not live in this team"),
        ("rover0", "range", [("time", base["time"])], TypeError, "mapping of column"),
        ("rover0", "range", None, TypeError, "mapping of column"),
    ]:
        with pytest.raises(error, match=text) as info:
            team.push(robot, table, row)
        assert str(info.value).startswith(f"robot {robot!r}, table {table!r}")
    assert team.rows == n + 2
    for row in rows[k:]:
        team.push(*row)
    _same(team.finish(), online)
    with pytest.raises(ValueError, match="after finish") as info:
        team.push(*rows[-1])
    assert str(info.value).startswith("robot ")
    assert team.rows == n + 2 + len(rows) - k


def test_a_raising_subscriber_leaves_the_team_whole(logs):
    """A callback that raises: every step of that push is still solved and every other
    subscriber called; the exception comes out of the push once the row is in; the team goes
    on to online's result, each update delivered once, in order."""
    log, run_dir, online = logs["loop"]
    team = LiveTeam.open(run_dir, window=2.0)  # a push releases several steps at once
    good, calls = [], []

    def bad(update):
        calls.append(update.step)
        if len(calls) == 3:
            raise RuntimeError("viewer bug")

    team.subscribe(bad)
    team.subscribe(good.append)
    raised = 0
    for row in log.pushes():
        try:
            team.push(*row)
        except RuntimeError as exc:
            assert str(exc) == "viewer bug"
            raised += 1
            assert team.solver.done == len(team.graph.steps)  # nothing left behind
            assert [u.step for u in good] == list(range(len(team.graph.steps)))
    result = team.finish()
    assert raised == 1
    assert calls == [u.step for u in good] == list(range(len(result.graph.steps)))
    _same(result, online)


def test_checkpoint_then_restart_loses_nothing(logs, tmp_path):
    """A team killed after its last checkpoint and opened again with the file replays every
    row pushed before it; the rows after it pushed again give online's result. A push refused
    with an error (unknown robot) before the checkpoint does not keep it from resuming."""
    log, run_dir, online = logs["far"]
    rows = log.pushes()
    ck = tmp_path / "team.checkpoint"
    team = LiveTeam.open(run_dir, checkpoint=ck, checkpoint_every=7)
    for i, row in enumerate(rows[: int(0.6 * len(rows))]):
        team.push(*row)
        if i == 100:
            with pytest.raises(ValueError, match="unknown robot"):
                team.push("ghost", "range", row[2])
    saved = len(read_checkpoint_file(ck, allow_nan=True)["live"]["rows"])
    assert 100 < saved < 0.6 * len(rows)
    del team  # killed
    again = LiveTeam.open(run_dir, checkpoint=ck, checkpoint_every=7)
    assert again.resumed == saved
    for row in rows[saved:]:
        again.push(*row)
    _same(again.finish(), online)


def test_a_wheel_run_the_wheel_route_does_not_cover_takes_the_event_route(logs, tmp_path):
    """A robot without an initial pose (nothing places it) and a wheel robot with a relative
    pose of its own: the event route takes the run (`live.wheel_steps`); the relative pose is
    a counted skip, the unplaced robot a counted `unanchored_robot` with no estimate, and the
    live team gives `graphloc online`'s estimates."""
    log, run_dir, _ = logs["loop"]
    manifest = json.loads((run_dir / "manifest.json").read_text())
    manifest["robots"][1].pop("initial_pose")
    manifest["robots"][2]["tables"]["relative_pose3"] = "rover2/relative_pose3.csv"
    sensor = next(s["name"] for s in manifest["robots"][2]["sensors"] if s["type"] == "odometry")
    other = tmp_path / "run"
    shutil.copytree(run_dir, other)
    (other / "manifest.json").write_text(json.dumps(manifest))
    (other / "rover2/relative_pose3.csv").write_text(
        "time,sensor,time0,tx,ty,tz,qx,qy,qz,qw,sigma_rx,sigma_ry,sigma_rz,sigma_tx,sigma_ty,"
        f"sigma_tz\n1.0,{sensor},0.5,0.1,0,0,0,0,0,1,0.01,0.01,0.01,0.01,0.01,0.01\n"
    )
    team = LiveTeam.open(other)
    for row in run_rows(other):
        team.push(*row)
    result = team.finish()
    online = graphloc.run_team(other, tmp_path / "online", "online").result
    for name in ("estimate", "causal"):  # the unplaced robot's rows all NaN
        for a, b in zip(getattr(result, name), getattr(online, name)):
            assert a.shape == b.shape and np.array_equal(np.isnan(a), np.isnan(b))
            assert np.nanmax(np.abs(a - b), initial=0.0) <= 1e-9
    for counts in (team.skips.counts, online.graph.skips.counts):
        assert counts["relative_pose_of_wheel_robot"] == 1
    unanchored = result.graph.skips.counts["unanchored_robot"]
    assert unanchored == online.graph.skips.counts["unanchored_robot"] > 0
    assert np.isnan(result.estimate[1]).all() and np.isfinite(result.estimate[0]).all()


@pytest.mark.slow
def test_six_robots_a_minute_live_is_online_and_consistent(tmp_path):
    sc = Scenario("loop", robots=6, duration=60.0, seed=11, measurement_hz=3.0)
    log = generate(sc)
    run_dir = write_log(log, tmp_path / "run")
    online = graphloc.run_team(run_dir, tmp_path / "online", "online").result
    team = LiveTeam.open(run_dir)
    nees = _nees(log, team)
    for row in log.pushes():
        team.push(*row)
    _same(team.finish(), online)
    assert len(nees) >= 6 * 200 and _consistent(nees), np.mean(nees)


@pytest.mark.parametrize("start_time", [True, False], ids=["start_time", "no-start_time"])
def test_a_static_robot_without_rows_has_its_pose_in_every_route(tmp_path, start_time):
    """A static robot with an initial pose and no tables (a beacon): its one pose at the start
    in the graph of its whole tables (`graphloc smooth` / `online`), of its rows one by one and
    a live team's, with or without the manifest's start_time."""
    from graphloc.datasets import open_run
    from graphloc.live.builder import build_live
    from graphloc.pipelines.team_graph import GraphConfig

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from helpers_live import _fed_in_chunks, _same_graph

    log = generate(Scenario("corridor", robots=2, duration=5.0, seed=5))
    manifest = dict(log.manifest)
    if not start_time:
        manifest.pop("start_time")
    beacon = {"name": "beacon", "kind": "post", "static": True, "initial_pose": [1.0, 2.0, 0.3]}
    manifest["robots"] = [*manifest["robots"], {**beacon, "sensors": [], "tables": {}}]
    run_dir = write_log(log, tmp_path / "run", manifest)
    run = open_run(run_dir)
    _same_graph(_fed_in_chunks(run, GraphConfig(), None), build_live(run, GraphConfig()))
    online = graphloc.run_team(run_dir, tmp_path / "online", "online").result
    team = _pushed(run_dir, log.pushes())
    result = team.finish()
    assert [len(e) for e in result.estimate][2] == 1
    np.testing.assert_allclose(result.estimate[2][0, :2], [1.0, 2.0], atol=1e-6)
    _same(result, online)


@pytest.mark.parametrize("window", ["0.5", None, True, float("nan"), -1.0])
def test_a_bad_window_is_a_clear_error(logs, window):
    _, run_dir, _ = logs["loop"]
    with pytest.raises(ValueError, match="window must be"):
        LiveTeam.open(run_dir, window=window)


def test_rows_of_a_static_robot_pushed_live_join_the_next_step(tmp_path):
    """A static robot that lists no tables (its rows pushed live, so `open` lets it in) ranging
    to a landmark: the factor is on its one pose at the start, a step long solved; it joins
    the next step (it raised an AssertionError from push, and every later push too)."""
    log = generate(Scenario("corridor", robots=2, duration=5.0, seed=5))
    manifest = dict(log.manifest)
    beacon = {"name": "beacon", "kind": "post", "static": True, "initial_pose": [1.0, 2.0, 0.0]}
    sensors = [{"name": "uwb", "type": "range"}]
    manifest["robots"] = [*manifest["robots"], {**beacon, "sensors": sensors, "tables": {}}]
    run_dir = write_log(log, tmp_path / "run", manifest)
    landmark = next(iter(log.landmarks))
    true_range = float(np.linalg.norm(log.landmarks[landmark] - [1.0, 2.0, 0.0]))
    team = LiveTeam.open(run_dir)
    rows = log.pushes()
    beacon_rows = 0
    for i, row in enumerate(rows):
        if i % 300 == 299:
            team.push(
                "beacon",
                "range",
                {
                    "time": row[2]["time"],
                    "sensor": "uwb",
                    "target": f"landmark:{landmark}",
                    "range": true_range,
                },
            )
            beacon_rows += 1
        team.push(*row)
    team.push(
        "beacon",
        "range",
        {
            "time": rows[-1][2]["time"],
            "sensor": "uwb",
            "target": f"landmark:{landmark}",
            "range": true_range,
        },
    )
    result = team.finish()
    assert beacon_rows >= 3
    assert not team.skips.counts  # the last one too: it joins the final step
    reference = _pushed(run_dir, rows).finish()
    ranges = result.graph.factor_types.count("landmark")
    assert ranges == reference.graph.factor_types.count("landmark") + beacon_rows + 1
    np.testing.assert_allclose(result.estimate[2][0, :3], [1.0, 2.0, 0.0], atol=1e-3)
