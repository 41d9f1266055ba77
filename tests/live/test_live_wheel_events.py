"""Wheel-odometry robots on the event route (`graphloc.live.wheel_steps`): a team that mixes
wheel odometry (`odometry`) with event-clocked robots (relative poses, marker pixels) is live --
`team_graph` builds it with `build_events` --, each wheel robot's grid
steps are the whole run's integration bit for bit however its rows are split, the steps up to a
time do not change when later rows exist, and the live team gives `graphloc online`'s
estimates. The mixed log is the outside user's generator (tests/foreign/team_generator.py,
layout mixed-team) with the ceiling camera's markers of one wheel robot. The wheel runs the
wheel route (`LiveGraph`) does not take -- static robots with bearings of their own, robots
without an initial pose placed by mutual bearings and resection -- take the event route too
(`_wheel_team`, from the generator's parts)."""

from __future__ import annotations

import json
import sys
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pytest

import graphloc
from graphloc.datasets import open_run
from benchmarks.planar_factors import integrate_unicycle
from graphloc.live import replay_live
from graphloc.live.coverage import route, run_tables
from graphloc.live.event_rows import build_events
from graphloc.live.wheel_steps import WheelSteps, wheel_motions
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.pipelines.team_graph.graph import factor_keys
from graphloc.pipelines.team_graph.motion import velocity_noise
from graphloc.runner.team_run import team_graph
from helpers_live import _same_estimates, _same_graph

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "foreign"))

import score  # noqa: E402
import team_generator as gen  # noqa: E402


def _mixed(root: Path, duration: float = 12.0, target: str = "rover_c") -> Path:
    """The generator's mixed team (wheel robots rover_a / rover_c, relative poses of rover_b,
    the ceiling and wall climbers, the ceiling camera without an initial pose), its camera's
    marker rows of `target` only (one stream places it)."""
    config = gen.GeneratorConfig(
        layout="mixed-team", seed=0, duration_s=duration, landmark_heights="sensor"
    )
    run = gen.generate(root / "mixed", config)
    markers = run / "ceiling" / "markers.csv"
    head, *rows = markers.read_text().splitlines()
    markers.write_text("\n".join([head, *(r for r in rows if r.split(",")[2] == target)]) + "\n")
    return run


def _wheel_team(out: Path, rover_placed: bool, duration: float = 20.0) -> Path:
    """Three static robots g1..g3 with omni bearings of each other and of a wheel-odometry
    rover (g1 with an initial pose and a range to g2: mutual bearings place g2 and g3), the
    rover with bearings of the three (with `rover_placed` False, resection places it)."""
    config = gen.GeneratorConfig(layout="mixed-team", seed=0, duration_s=duration)
    rng, noise = np.random.default_rng(0), config.noise
    log = gen.Log("wheel-team", [], duration=duration)
    sim = gen.Sim(config, log, rng)
    omni = {"bearing_sigma": noise.omni_bearing_sigma}
    statics = []
    for i, (x, y) in enumerate([(2.5, 2.0), (-2.8, 1.5), (0.3, -2.6)], start=1):
        g = gen._ground(rng, sim, f"g{i}", None, moving=False, duration=duration,
                        start=(x, y, rng.uniform(-3, 3)))  # fmt: skip
        g.initial_pose = i == 1
        sim.mount(g, "omni", "bearing", [0.0, 0.0, 0.25], [0, 0, rng.uniform(-3, 3)], omni)
        statics.append(g)
    tape = {"range_sigma": noise.range_sigma, "range_sigma_per_m": 0.0}
    sim.mount(statics[0], "tape", "range", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], tape)
    rover = gen._ground(rng, sim, "rover", None, moving=True, duration=duration,
                        region=(-1.5, 1.5, -1.0, 1.0))  # fmt: skip
    rover.initial_pose = rover_placed
    sim.odometry_sensor(rover, wheel=True)
    sim.mount(rover, "omni", "bearing", [0.0, 0.0, 0.25], [0, 0, rng.uniform(-3, 3)], omni)
    log.robots = [*statics, rover]
    sim.wheel_odometry(rover)
    names = [g.name for g in statics]
    for g in statics:
        others = [n for n in [*names, "rover"] if n != g.name]
        sim.bearings(g, "omni", others, gen.frame_times(4.0, duration), omni["bearing_sigma"])
    sim.ranges(statics[0], "tape", [names[1]], [0.0], per_m=0.0)
    sim.bearings(rover, "omni", names, gen.frame_times(0.5, duration), omni["bearing_sigma"])
    meta = {"config": asdict(config), "conventions": gen.CONVENTIONS, "true_layouts": {}}
    gen.write_log(log, out, meta)
    return out


@pytest.fixture(scope="module")
def mixed(tmp_path_factory) -> Path:
    return _mixed(tmp_path_factory.mktemp("wheel-events"))


def test_a_mixed_team_is_live_on_the_event_route(mixed):
    """Wheel robots beside relative-pose and marker robots: nothing keeps the run off the live
    builder; `team_graph` builds the event route's graph, every wheel robot's pose times the
    grid start + k keyframe_dt and its measurements' times inside a step."""
    run, config = open_run(mixed), GraphConfig()
    tables = run_tables(run)
    assert {"odometry", "relative_pose3", "candidates"} <= set().union(*tables.values())
    assert route(run, tables) == "event"
    graph = team_graph(run, config)
    _same_graph(build_events(run, config), graph)
    for r in (1, 3):  # rover_a, rover_c: wheel odometry
        times, end = graph.node_times[r], run.velocity[r][-1, 0]
        grid = run.start_time + config.keyframe_dt * np.arange(int(end / config.keyframe_dt) + 1)
        assert np.isin(np.round(grid, 9), times).all()
        between = times[~np.isin(times, np.round(grid, 9))]
        measured = [p.time for p in run.points if r in (p.robot, p.target)]
        measured += [o.time for o in run.observations if o.target == r]
        assert len(between) and np.isin(between, np.round(measured, 9)).all()
    assert graph.counts["committed_sets"] > 0 and not graph.skips.counts.get("unanchored_robot")


def test_wheel_steps_are_the_whole_run_integration_however_the_rows_are_split(mixed):
    """Rows in random chunks: the grid steps, their times and covariances are those of
    `integrate_unicycle` over the whole table (`motion._velocity_steps`), bit for bit, each made
    by the first row at or after its end."""
    run, config = open_run(mixed), GraphConfig()
    rng = np.random.default_rng(5)
    for r in (1, 3):
        rows = run.velocity[r]
        wheel, made, i = WheelSteps(r, run, config), [], 0
        while i < len(rows):
            j = min(len(rows), i + int(rng.integers(1, 9)))
            wheel.add(rows[i:j])
            made += wheel.steps(run.start_time)
            i = j
        grid = run.start_time + config.keyframe_dt * np.arange(len(made) + 1)
        ref = integrate_unicycle(*rows.T, grid, velocity_noise(run, r, config))
        assert len(made) == len(ref.deltas) > 0
        for (t, m), d, t0, t1 in zip(made, ref.deltas, grid[:-1], grid[1:]):
            assert (m.robot, m.t0, m.t1) == (r, t0, t1)
            assert t == rows[np.searchsorted(rows[:, 0], t1 - 1e-9 * config.keyframe_dt), 0]
            assert np.array_equal(np.r_[m.relative.x(), m.relative.y()], d[:2])
        whole = [m for _, m in wheel_motions(run, config) if m.robot == r]
        assert [(m.t0, m.t1) for m in whole] == [(m.t0, m.t1) for _, m in made]
        for a, (_, b) in zip(whole, made):
            assert np.array_equal(a.relative.matrix(), b.relative.matrix())
            assert np.array_equal(a.covariance, b.covariance)


def test_the_steps_up_to_a_time_do_not_change_when_later_rows_exist(mixed):
    """Causal: the run cut at a time (every row after it withheld) emits the whole run's
    steps up to there, with the same factors."""
    run, config = open_run(mixed), GraphConfig()
    whole = build_events(run, config)
    cut = 0.5 * (run.start_time + run.velocity[1][-1, 0])
    part = replace(
        run,
        velocity=tuple(v[v[:, 0] <= cut] for v in run.velocity),
        motions=tuple(m for m in run.motions if max(m.t0, m.t1) <= cut),
        observations=tuple(o for o in run.observations if o.time <= cut),
        points=tuple(p for p in run.points if p.time <= cut),
    )
    emitted: list = []
    build_events(part, config, emitted)
    early = [step for steps in emitted[:-1] for step in steps]  # before `finish`
    assert len(early) > len(whole.steps) // 4
    assert [t for t, _ in early] == [t for t, _ in whole.steps[: len(early)]]
    for (_, fa), (_, fb) in zip(early, whole.steps):
        assert [factor_keys(f) for f, _ in fa] == [factor_keys(f) for f, _ in fb]


def test_live_team_of_a_mixed_run_is_graphloc_online(mixed, tmp_path):
    """The log's rows (odometry, relative poses, marker pixels, ranges and bearings) pushed in
    time order through the live API give `run_team(..., "online")`'s estimates and causal
    estimates, every robot estimated."""
    updates: list = []
    team = replay_live(mixed, subscriber=updates.append)
    result = team.finish()
    online = graphloc.run_team(mixed, tmp_path / "out", "online").result
    _same_estimates(result, online)
    assert [u.step for u in updates] == list(range(len(result.graph.steps)))
    for estimate in result.estimate:
        assert np.isfinite(estimate[:, :3]).any()


@pytest.mark.parametrize("rover_placed", [True, False])
def test_wheel_runs_the_wheel_route_does_not_take_are_live_on_the_event_route(
    tmp_path, rover_placed
):
    """Static robots with bearings of their own, two without an initial pose (mutual
    bearings), a wheel rover with or without one (resection on its bearings of the three):
    the event route builds the run (`team_graph`, no whole-run builder), smooth and online
    place every robot near the truth, smooth calls itself consistent, and the live team gives
    online's estimates. (Online's verdict is not asserted: iSAM2 relinearizes a wheel run at
    COARSE_PRECISION, `config.run_precision`, which leaves the rover's sensor ties beyond
    their noise here -- the deleted whole-run builder's online pass did the same on this run.)"""
    source = _wheel_team(tmp_path / "run", rover_placed)
    run = open_run(source)
    tables = run_tables(run)
    assert route(run, tables) == "event"
    _same_graph(build_events(run, GraphConfig()), team_graph(run, GraphConfig()))
    results = {}
    for verb, mode in (("smooth", "batch"), ("online", "online")):
        done = graphloc.run_team(source, tmp_path / verb, mode)
        assert mode == "online" or done.metrics["consistent"], done.metrics["consistency"]
        scores = score.score(source, tmp_path / verb, mode)
        assert not scores["unplaced"]
        for name, robot in scores["robots"].items():
            assert robot["rmse_m"] < 0.1 and robot["final_m"] < 0.1, (verb, name, robot)
        results[mode] = done.result
    _same_estimates(replay_live(source).finish(), results["online"])


def test_a_mixed_run_without_a_start_time_starts_where_the_reader_does(tmp_path):
    """No start_time in the manifest and rover_a's odometry from 0.35 s: the live team waits
    for every wheel robot's first row and starts at the latest (the log reader's start, 0.4 s
    -- a grid that puts the camera's frames inside the target's steps), holding the relative
    poses until then; it gives the estimates of online's graph."""
    source = _mixed(tmp_path)
    manifest = json.loads((source / "manifest.json").read_text())
    del manifest["start_time"]
    (source / "manifest.json").write_text(json.dumps(manifest))
    odometry = source / "rover_a" / "odometry.csv"
    head, *rows = odometry.read_text().splitlines()
    late = [row for row in rows if float(row.split(",")[0]) >= 0.35]
    odometry.write_text("\n".join([head, *late]) + "\n")
    run = open_run(source)
    assert run.start_time == float(late[0].split(",")[0])
    online = solve(team_graph(run, GraphConfig()), "online")
    live = replay_live(source).finish()
    assert live.graph.run.start_time == run.start_time
    _same_estimates(live, online)


@pytest.mark.slow
def test_the_foreign_mixed_team_live_is_graphloc_online(tmp_path):
    """tests/team_graph/test_foreign_runs.py's mixed-team log (wheel rovers, a relative-pose
    rover, two climbers, the ceiling camera's marker sets of four targets): live, every row
    pushed in time order, gives online's estimates and causal estimates."""
    config = gen.GeneratorConfig(
        layout="mixed-team", seed=0, duration_s=40.0, landmark_heights="sensor"
    )
    source = gen.generate(tmp_path / "mixed", config)
    run = open_run(source)
    assert route(run, run_tables(run)) == "event"
    online = solve(team_graph(run, GraphConfig()), "online")
    _same_estimates(replay_live(source).finish(), online)
