"""The live API (`graphloc.live`): rows pushed in time order give the steps, factors and initial
values of the whole-run builder and the estimates of `graphloc online`; rows shuffled within the
window the same; late and bad rows counted skips; runs that need sections not live yet refused
at open, naming them."""

from __future__ import annotations

import heapq
import random
from dataclasses import replace
from pathlib import Path

import gtsam
import numpy as np
import pytest

import graphloc
from graphloc.datasets import open_run
from graphloc.factors.odometry import VelocityNoise, integrate_unicycle
from graphloc.live import LiveTeam, NotLiveError, replay, replay_live, run_rows
from graphloc.live.arc import ArcIntegrator
from graphloc.live.builder import LiveGraph
from graphloc.live.setup import empty_run
from graphloc.pipelines.team_graph import GraphConfig, build_graph
from graphloc.pipelines.team_graph.graph import factor_keys

DATASET6 = Path(__file__).resolve().parents[1].parent / "shared/data/mrclam/MRCLAM_Dataset6"
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


def _feed_in_time_order(run, config) -> LiveGraph:
    """A loaded run's odometry rows and point measurements into a `LiveGraph`, merged in time
    order, the graph advanced after each."""
    live = LiveGraph(empty_run(run), config, run.start_time)

    def odometry(r):
        return ((row[0], 0, r, row) for row in run.velocity[r])

    streams = [odometry(r) for r in range(len(run.robots))]
    streams.append((m.time, 1, -1, m) for m in run.points)
    for t, kind, r, item in heapq.merge(*streams, key=lambda e: e[0]):
        live.velocity(r, item) if kind == 0 else live.point(item)
        live.advance(t)
    live.finish()
    return live


def _same_graph(ref, graph) -> None:
    for a, b in zip(ref.node_times, graph.node_times):
        assert np.array_equal(a, b)
    assert [t for t, _ in ref.steps] == [t for t, _ in graph.steps]
    assert ref.factor_types == graph.factor_types
    for (_, fa), (_, fb) in zip(ref.steps, graph.steps):
        assert [factor_keys(f) for f, _ in fa] == [factor_keys(f) for f, _ in fb]
    assert ref.initial.keys() == graph.initial.keys()
    values = gtsam.Values()
    for key, value in ref.initial.items():
        other = graph.initial[key]
        if isinstance(value, gtsam.Pose3):
            assert np.array_equal(value.matrix(), other.matrix())
        else:
            assert np.array_equal(np.asarray(value), np.asarray(other))
        values.insert(key, value)
    errors = [[f.error(values) for f, _ in group] for _, group in ref.steps]
    assert errors == [[f.error(values) for f, _ in group] for _, group in graph.steps]
    assert ref.counts == graph.counts
    assert ref.skips.counts == graph.skips.counts


@pytest.mark.parametrize(
    "config",
    [
        GraphConfig(),
        GraphConfig(landmark_priors=False),  # SLAM: landmark guesses from the first pose
        GraphConfig(anchor_known_landmarks=False, keyframe_dt=0.1),
    ],
    ids=["known", "slam", "shared-landmarks"],
)
def test_live_graph_is_the_whole_run_graph(planar_log, config):
    run = open_run(planar_log)
    _same_graph(build_graph(run, config), _feed_in_time_order(run, config).graph)


@needs_dataset6
def test_live_graph_is_the_whole_run_graph_on_dataset6():
    run = open_run(DATASET6, duration=30.0)
    config = GraphConfig()
    _same_graph(build_graph(run, config), _feed_in_time_order(run, config).graph)


def _same_estimates(result, reference, tol: float = 1e-9) -> None:
    assert len(result.estimate) == len(reference.estimate)
    for name in ("estimate", "causal"):
        for a, b in zip(getattr(result, name), getattr(reference, name)):
            assert a.shape == b.shape
            assert np.array_equal(np.isnan(a), np.isnan(b))
            assert np.nanmax(np.abs(a - b), initial=0.0) <= tol


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
    assert message.startswith(f"robot {late[0]!r}, table 'range_bearing': time ")
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


@pytest.mark.parametrize(
    "scenario, missing",
    [
        ("feng-probabilistic", ["table 'markers'", "climber: no initial_pose"]),
        ("dual-robot-room", ["table 'scans'"]),
        ("crawler-pair", ["table 'ellipses'", "table 'features'", "table 'relative_pose3'"]),
    ],
)
def test_a_run_not_live_yet_is_refused_at_open(tmp_path, scenario, missing):
    from graphloc.datasets.scenarios import generate

    generate(scenario, tmp_path / "run", 1)
    with pytest.raises(NotLiveError) as info:
        LiveTeam.open(tmp_path / "run")
    for text in missing:
        assert text in str(info.value)


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
