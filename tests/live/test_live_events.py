"""The event-clocked live builder (`graphloc.live.events.EventGraph`): robots without wheel
odometry, placed by the candidate sets they see of a static target, built row by row in time
order -- each step emitted as soon as it is complete and solved then -- give the graph built
from the whole tables (`team_graph`, what `graphloc smooth` / `online` solve) and the estimates
of `graphloc online`; a row that is not causal is a counted skip, named."""

from __future__ import annotations

import re
from dataclasses import replace

import gtsam
import numpy as np
import pytest

import graphloc
from graphloc.datasets import open_run
from graphloc.datasets.scenarios import generate
from graphloc.live import LiveTeam, NotLiveError, replay_live
from graphloc.live.builder import build_live
from graphloc.live.coverage import route, run_tables
from graphloc.live.event_rows import build_events
from graphloc.keys import decode, pose_key
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.pipelines.team_graph.graph import factor_keys
from graphloc.pipelines.team_graph.passes import Pass
from graphloc.run import Motion
from graphloc.runner.team_run import team_graph
from helpers_live import _event_graph, _live, _rows, _same_estimates, _same_graph

CASES = [(name, seed) for name in ("breitenmoser-target", "feng-probabilistic") for seed in (1, 2)]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("event-runs")
    out = {}
    for name, seed in CASES + [("kaushik-p3p-error", 1)]:
        generate(name, root / f"{name}-{seed}", seed)
        out[(name, seed)] = open_run(root / f"{name}-{seed}")
    return out


@pytest.mark.parametrize("name, seed", CASES)
def test_event_graph_row_by_row_is_the_graph_of_the_whole_tables(runs, name, seed):
    """Rows in time order, `advance` after each: the steps come out as the rows complete them
    (all but the last before `finish`), and the graph is the one built from the whole tables
    (`team_graph`: what the verbs solve)."""
    run, config = runs[(name, seed)], GraphConfig()
    emitted = []
    live = _live(run, config, emitted.append)
    ref = team_graph(run, config)
    _same_graph(ref, live.graph)
    assert len(emitted[-1]) <= 1 < len(ref.steps)  # only the last step waits for the end
    assert sum(map(len, emitted)) == len(ref.steps)
    assert [d.status for d in live.graph.decisions] == [d.status for d in ref.decisions]
    assert live.graph.anchored_from == ref.anchored_from
    # graphloc online's route for the loaded run: the event builder
    assert route(run, run_tables(run)) == "event"


@pytest.mark.parametrize("name, seed", CASES)
def test_event_graph_solved_step_by_step_is_graphloc_online(runs, name, seed):
    """Each step solved by the online pass as soon as it is emitted (the observer's factors
    held until its first decided set: `anchored_from` unknown until then) gives the estimates
    and causal estimates of `solve(team_graph(run), "online")` exactly."""
    run, config = runs[(name, seed)], GraphConfig()
    reference = solve(team_graph(run, config), "online")
    assert reference.hypotheses == 1
    solver = None

    def step(steps):
        for _ in steps:
            solver.step(solver.done)

    live = _event_graph(run, config)
    solver = Pass(live.graph, "online", None, False, None)
    assert solver.hold_until == np.inf  # robots are held until the builder places them
    for t, kind, row in _rows(run):
        (live.motion if kind == 0 else live.observation)(row)
        step(live.advance(t))
    step(live.finish())
    live.graph.run = run
    _same_estimates(solver.result(), reference, tol=1e-9)


def test_a_stream_never_decided_places_its_observer_by_the_guess_after_some_sets(runs):
    """kaushik-p3p-error: no set is ever decided; the camera is placed at its
    `guess_after_sets`-th tracked set by the tracker's best guess there (the candidate of
    highest posterior), its factors held until then -- for any wait, at that set;
    another set; the run goes through `build_live`, no whole-run builder."""
    run = runs[("kaushik-p3p-error", 1)]
    for wait in (1, 3, GraphConfig().guess_after_sets):
        config = replace(GraphConfig(), guess_after_sets=wait)
        live = _live(run, config)
        assert all(d.status == "undecided" for d in live.graph.decisions)
        tracker = live.streams[(0, 1, True)][0]
        placing = tracker.out.sets[wait - 1]
        assert live.graph.anchored_from[0] == live.graph.node_times[0][placing.k]
        best = placing.bodies[int(np.argmax(placing.update.probabilities))]
        placed = live.graph.initial[pose_key(0, placing.k)]
        assert np.array_equal(placed.matrix(), best.matrix())
        assert not live.skips.counts.get("unanchored_robot")
    assert route(run, run_tables(run)) == "event"
    _same_graph(live.graph, build_live(run, GraphConfig()))


@pytest.mark.parametrize("name, seed", [*CASES, ("kaushik-p3p-error", 1)])
def test_the_steps_up_to_a_time_do_not_change_when_later_rows_exist(runs, name, seed):
    """Causal: the run cut at a time t (every row after it withheld) emits before its end the
    same steps -- times, factors, initial values, placement -- as the whole run does up to
    there; nothing built before t waits for what comes after it."""
    run, config = runs[(name, seed)], GraphConfig()
    whole = build_events(run, config)
    times = [t for t, _, _ in _rows(run)]
    for cut in (times[len(times) // 3], times[2 * len(times) // 3]):
        part = replace(
            run,
            motions=tuple(m for m in run.motions if max(m.t0, m.t1) <= cut),
            observations=tuple(o for o in run.observations if o.time <= cut),
        )
        emitted = []
        live = _live(part, config, emitted.append)
        early = [step for steps in emitted[:-1] for step in steps]  # before `finish`
        assert early and len(early) < len(whole.steps)
        prefix = replace(whole, steps=whole.steps[: len(early)])
        assert [t for t, _ in early] == [t for t, _ in prefix.steps]
        for (_, fa), (_, fb) in zip(early, prefix.steps):
            assert [factor_keys(f) for f, _ in fa] == [factor_keys(f) for f, _ in fb]
            assert [kind for _, kind in fa] == [kind for _, kind in fb]
        for key in {k for _, group in early for f, _ in group for k in factor_keys(f)}:
            if key not in live.graph.initial:  # a robot not placed by the cut: held
                assert decode(key)[1] not in live.graph.anchored_from
                continue
            if live.graph.anchored_from.get(decode(key)[1], -np.inf) > early[-1][0]:
                continue  # placed after these steps (a stream placed when the cut run ended)
            a, b = live.graph.initial[key], whole.initial[key]
            a, b = (a.matrix(), b.matrix()) if isinstance(a, gtsam.Pose3) else (a, b)
            assert np.array_equal(np.asarray(a), np.asarray(b))
        for r, t in live.graph.anchored_from.items():
            if t <= early[-1][0]:
                assert whole.anchored_from[r] == t


def test_a_step_starting_inside_built_steps_is_a_counted_skip(runs):
    """A relative pose whose start lies inside steps already built would split them (its stamp
    a new pose among final ones), a candidate set older than the built poses would add one:
    each a counted skip naming it as it arrives (a live team's late row), the built steps and
    the rows that follow unchanged."""
    run = runs[("feng-probabilistic", 1)]
    live = _event_graph(run, GraphConfig())
    rows = _rows(run)
    for t, kind, row in rows[:40]:
        (live.motion if kind == 0 else live.observation)(row)
        live.advance(t)
    built = live.graph.node_times[0]
    assert len(built) > 5
    t0 = 0.5 * (built[2] + built[3])
    late = Motion(0, t0, rows[40][0], gtsam.Pose3(), np.eye(6) * 1e-4)
    live.motion(late)
    early = next(row for _, kind, row in rows[:40] if kind == 1)  # a set before the built times
    live.observation(early)
    assert live.skips.counts == {"relative_pose_late": 1, "set_late": 1}
    examples = "\n".join(live.skips.examples)
    assert "climber: a relative pose from" in examples and "inside steps already built" in examples
    assert re.search(r"climber: a candidate set at \S+, after its pose times", examples)
    for t, kind, row in rows[40:]:
        (live.motion if kind == 0 else live.observation)(row)
        live.advance(t)
    live.finish()
    whole = build_live(run, GraphConfig())
    assert [t for t, _ in live.graph.steps] == [t for t, _ in whole.steps]


def test_sets_of_a_target_nothing_places_are_counted_skips_on_the_live_route(runs):
    """feng-probabilistic with its static target's initial_pose removed: neither the climber
    nor its target has a pose, so no max-mixture places one through the other. The run is
    live (`team_graph` builds it with the event route): every set a
    counted `target_unplaced` skip, and each robot nothing
    placed a counted `unanchored_robot` naming it, its poses left out (no factor)."""
    run = runs[("feng-probabilistic", 1)]
    unplaced = replace(
        run, robots=tuple(replace(r, initial_pose=None) if r.static else r for r in run.robots)
    )
    graph = team_graph(unplaced, GraphConfig())
    sets = len(run.observations)
    assert graph.skips.counts["target_unplaced"] == sets
    poses = [len(t) for t in graph.node_times]
    assert graph.skips.counts["unanchored_robot"] == sum(poses) and poses[0] == sets
    assert sum(map(len, (group for _, group in graph.steps))) == 0
    assert any(f"climber: {sets} candidate sets on robot ground" in e for e in graph.skips.examples)
    assert any("robot ground:" in e and "left out" in e for e in graph.skips.examples)
    result = solve(graph, "online")
    assert all(np.isnan(e).all() for e in result.estimate)


@pytest.mark.parametrize("name, seed", CASES)
def test_live_team_is_graphloc_online(runs, name, seed, tmp_path):
    """The log's rows (relative poses, marker pixels) pushed in time order through the live
    API: the marker images made into candidate sets as the window passes them, every step one
    update, the estimates and causal estimates of `run_team(..., "online")`; an observer
    placed late gets no pose before its first decided set."""
    source = tmp_path / "run"
    generate(name, source, seed)
    updates = []
    team = replay_live(source, subscriber=updates.append)
    result = team.finish()
    online = graphloc.run_team(source, tmp_path / "out", "online").result
    _same_estimates(result, online)
    assert [u.step for u in updates] == list(range(len(result.graph.steps)))
    first = result.graph.anchored_from[0]
    seen = [u.time for u in updates if "climber" in u.poses]
    assert seen and min(seen) == first
    estimated = np.flatnonzero(np.isfinite(result.estimate[0][:, 0]))
    assert team.latest("climber").index == estimated[-1]


def test_kaushik_live_online_and_smooth_take_one_graph(tmp_path):
    """kaushik-p3p-error (never decided): the live team, `graphloc online` and `graphloc
    smooth` build the event route's graph: live gives online's estimates and causal
    estimates, the camera placed by its tracker's guess with every candidate of that set a
    hypothesis, and estimated."""
    source = tmp_path / "run"
    generate("kaushik-p3p-error", source, 1)
    team = replay_live(source)
    result = team.finish()
    online = graphloc.run_team(source, tmp_path / "out", "online").result
    _same_estimates(result, online)
    # placed by the guess at its `guess_after_sets`-th set: every candidate of that set a
    # hypothesis the online solve runs (the guess may be the wrong one)
    guesses = result.graph.guessed_alternatives
    assert online.hypotheses == 1 + len(guesses) > 1
    assert not team.skips.counts.get("unanchored_robot")
    assert np.isfinite(online.estimate[0]).all()
    smooth = graphloc.run_team(source, tmp_path / "smooth", "batch").result
    _same_graph(build_live(open_run(source), GraphConfig()), smooth.graph)
    assert np.isfinite(smooth.estimate[0]).all()


def test_a_stream_that_ends_before_its_guess_places_the_observer_at_its_last_set(tmp_path):
    """kaushik-p3p-error with fewer frames than `guess_after_sets`, none decided: when the run
    ends, the camera is placed at its stream's last set by the tracker's guess there, every
    candidate of that set a hypothesis; live, online and smooth estimate it, live gives
    online's estimates, nothing is left out. (Four frames of this scenario's erroneous P3P do
    not always tell the candidates apart: the estimate is near the truth, not at it.)"""
    source = tmp_path / "run"
    frames = GraphConfig().guess_after_sets - 1
    generate("kaushik-p3p-error", source, 1, overrides={"frames": str(frames)})
    team = replay_live(source)
    result = team.finish()
    online = graphloc.run_team(source, tmp_path / "out", "online")
    _same_estimates(result, online.result)
    run = open_run(source)
    last = max(o.time for o in run.observations)
    assert online.result.graph.anchored_from[0] == last
    assert online.result.hypotheses == 1 + len(online.result.graph.guessed_alternatives) > 1
    assert not online.result.graph.skips.counts.get("unanchored_robot")
    smooth = graphloc.run_team(source, tmp_path / "smooth", "batch")
    for solved in (result, online.result, smooth.result):
        assert np.isfinite(solved.estimate[0]).all() and np.isfinite(solved.estimate[1]).all()
    ate = smooth.metrics["per_robot"][run.robots[0].name]["batch"]["ate_rmse"]
    assert ate < 1.0 and smooth.metrics["consistent"], smooth.metrics["per_robot"]


def test_an_event_team_counts_bad_rows_and_refuses_odometry_of_a_robot_without_its_table(
    tmp_path,
):
    """Rows of an event-clocked team are checked as a log's (a counted skip naming robot,
    table, row and field); wheel odometry of a robot whose manifest has no odometry table (its
    pose times at its relative poses) is refused naming it."""
    source = tmp_path / "run"
    generate("feng-probabilistic", source, 1)
    team = LiveTeam.open(source)
    marker = {"time": 0.0, "sensor": "camera", "target": "ground", "marker": 0, "u": 1.0}
    team.push("climber", "markers", {**marker, "v": "nan"})
    team.push("climber", "markers", {**marker, "target": "nobody", "v": 2.0})
    step = {"time": 0.3, "sensor": "odometry", "time0": 0.0, "tx": 0.1, "ty": 0.0, "tz": 0.0}
    rotation = {"qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 0.0}
    sigmas = {f"sigma_{c}": 0.01 for c in ("rx", "ry", "rz", "tx", "ty", "tz")}
    team.push("climber", "relative_pose3", {**step, **rotation, **sigmas})
    counts = team.skips.counts
    assert counts.get("non_finite") == counts.get("unknown_target") == 1
    assert counts.get("bad_relative_pose") == 1  # a zero quaternion
    examples = "\n".join(team.skips.examples)
    assert "robot 'climber', table 'markers', row 1: field 'v'" in examples
    team.push("climber", "odometry", {"time": 0.0, "sensor": "odometry", "v": 0, "omega": 0})
    with pytest.raises(NotLiveError, match="robot climber: wheel odometry, but its manifest"):
        team.finish()
