"""The event-clocked live builder (`graphloc.live.events.EventGraph`): robots without wheel
odometry, placed by the candidate sets they see of a static target, built row by row in time
order -- each step emitted as soon as it is complete and solved then -- give the graph of
`build_graph` and the estimates of `graphloc online`; what is not causal is refused, named."""

from __future__ import annotations

import heapq

import gtsam
import numpy as np
import pytest

import graphloc
from graphloc.datasets import open_run
from graphloc.datasets.scenarios import generate
from graphloc.live import LiveTeam, NotLiveError, replay_live
from graphloc.live.builder import build_live
from graphloc.live.coverage import not_live, route, run_tables
from graphloc.live.event_rows import _without_rows, build_events
from graphloc.live.events import EventGraph
from graphloc.pipelines.team_graph import GraphConfig, build_graph, solve
from graphloc.pipelines.team_graph.passes import Pass
from graphloc.run import Motion
from test_live import _same_estimates, _same_graph

CASES = [(name, seed) for name in ("breitenmoser-target", "feng-probabilistic") for seed in (1, 2)]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("event-runs")
    out = {}
    for name, seed in CASES + [("kaushik-p3p-error", 1)]:
        generate(name, root / f"{name}-{seed}", seed)
        out[(name, seed)] = open_run(root / f"{name}-{seed}")
    return out


def _rows(run):
    """The run's relative poses (at their end time) and candidate sets, in time order."""
    motions = ((max(m.t0, m.t1), 0, i, m) for i, m in enumerate(run.motions))
    sets = ((o.time, 1, i, o) for i, o in enumerate(run.observations))
    return [(t, kind, row) for t, kind, _, row in heapq.merge(motions, sets, key=lambda e: e[:3])]


def _event_graph(run, config) -> EventGraph:
    """An empty `EventGraph` of the run's robots (its tables: relative poses, candidate sets)."""
    stamped, observers = {m.robot for m in run.motions}, {o.robot for o in run.observations}
    return EventGraph(_without_rows(run), config, run.start_time, stamped, observers)


def _live(run, config, on_steps=lambda steps: None) -> EventGraph:
    live = _event_graph(run, config)
    for t, kind, row in _rows(run):
        (live.motion if kind == 0 else live.observation)(row)
        on_steps(live.advance(t))
    on_steps(live.finish())
    return live


@pytest.mark.parametrize("name, seed", CASES)
def test_event_graph_is_the_whole_run_graph(runs, name, seed):
    """Rows in time order, `advance` after each: the steps come out as the rows complete them
    (all but the last before `finish`), and the graph is `build_graph`'s."""
    run, config = runs[(name, seed)], GraphConfig()
    emitted = []
    live = _live(run, config, emitted.append)
    ref = build_graph(run, config)
    _same_graph(ref, live.graph)
    assert len(emitted[-1]) <= 1 < len(ref.steps)  # only the last step waits for the end
    assert sum(map(len, emitted)) == len(ref.steps)
    assert [d.status for d in live.graph.decisions] == [d.status for d in ref.decisions]
    assert live.graph.anchored_from == ref.anchored_from
    # graphloc online's route for the loaded run: the event builder, the same graph
    assert not not_live(run, run_tables(run)) and route(run, run_tables(run)) == "event"
    _same_graph(ref, build_live(run, config))


@pytest.mark.parametrize("name, seed", CASES)
def test_event_graph_solved_step_by_step_is_graphloc_online(runs, name, seed):
    """Each step solved by the online pass as soon as it is emitted (the observer's factors
    held until its first decided set: `anchored_from` unknown until then) gives the estimates
    and causal estimates of `solve(build_graph(run), "online")` exactly."""
    run, config = runs[(name, seed)], GraphConfig()
    reference = solve(build_graph(run, config), "online")
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


def test_a_stream_never_decided_is_refused_naming_the_dependency(runs):
    """kaushik-p3p-error: no set is ever decided; graphloc online places the camera by the
    tracker's guess at the first set and runs that set's candidates as hypotheses -- a choice
    that depends on every later set."""
    run = runs[("kaushik-p3p-error", 1)]
    assert all(d.status != "decided" for d in build_graph(run, GraphConfig()).decisions)
    with pytest.raises(NotLiveError, match="never decided.*not causal"):
        build_events(run, GraphConfig())


def test_a_step_starting_inside_built_steps_is_refused(runs):
    """A relative pose whose start lies inside steps already built would split them (its stamp
    a new pose among final ones), a candidate set older than the built poses would add one:
    refused as they arrive, not silently rebuilt."""
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
    with pytest.raises(NotLiveError, match="inside steps already built"):
        live.motion(late)
    early = next(row for _, kind, row in rows[:40] if kind == 1)  # a set before the built times
    with pytest.raises(NotLiveError, match="candidate set at .* after its pose times"):
        live.observation(early)


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


def test_live_team_counts_a_never_decided_observer(tmp_path):
    """kaushik-p3p-error: the live team holds the camera's factors waiting for a decision that
    never comes; its poses are left out, counted as `unanchored_robot` naming why (graphloc
    online, with the whole run, places it by the guess and runs its hypotheses)."""
    source = tmp_path / "run"
    generate("kaushik-p3p-error", source, 1)
    team = replay_live(source)
    result = team.finish()
    assert team.skips.counts["unanchored_robot"] == len(result.node_times[0]) > 0
    assert any("never decided" in e for e in team.skips.examples)
    assert np.isnan(result.estimate[0]).all() and np.isfinite(result.estimate[1]).all()
    online = graphloc.run_team(source, tmp_path / "out", "online").result
    assert online.hypotheses == 1 + len(online.graph.guessed_alternatives) > 1
    assert np.isfinite(online.estimate[0]).all()


def test_an_event_team_counts_bad_rows_and_refuses_wheel_odometry(tmp_path):
    """Rows of an event-clocked team are checked as a log's (a counted skip naming robot,
    table, row and field); a table of the other route is refused naming it."""
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
    with pytest.raises(NotLiveError, match="'odometry' is not live in this team"):
        team.push("climber", "odometry", {"time": 0.0, "sensor": "wheels", "v": 0, "omega": 0})
