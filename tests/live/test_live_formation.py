"""The event-clocked live builder on seed 000 Sec. VI-A (feng-deterministic): three static
ground robots placed by mutual bearings, a climber resected by P3P on its bearings of them
(`graphloc.live.event_points`) -- built row by row, the graph is the one built from the whole
tables, each step emitted once the placements it needs are made, and the live team
(hypotheses from every P3P candidate) gives `graphloc online`'s estimates."""

from __future__ import annotations

import heapq
from dataclasses import replace

import gtsam
import numpy as np
import pytest

import graphloc
from graphloc.cli import main
from graphloc.datasets import open_run
from graphloc.datasets.scenarios import generate
from graphloc.keys import decode
from graphloc.live import LiveTeam, replay_live
from graphloc.live.builder import build_live
from graphloc.live.coverage import route, run_tables
from graphloc.live.event_rows import build_events
from graphloc.live.setup import empty_run
from graphloc.live.events import EventGraph
from graphloc.pipelines.team_graph import GraphConfig, run_precision
from graphloc.runner.team_run import team_graph
from graphloc.pipelines.team_graph.graph import factor_keys
from graphloc.run import Motion
from helpers_live import _same_estimates, _same_graph

SEEDS = (1, 3)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("formation-runs")
    for seed in SEEDS:
        generate("feng-deterministic", root / str(seed), seed)
    return root


def _rows(run):
    """Relative poses (at their end time), point measurements: in time order."""
    motions = ((max(m.t0, m.t1), 0, i, m) for i, m in enumerate(run.motions))
    points = ((m.time, 1, i, m) for i, m in enumerate(run.points))
    return [(t, kind, row) for t, kind, _, row in heapq.merge(motions, points, key=lambda e: e[:3])]


def _feed(run, config, rows, emitted) -> EventGraph:
    live = EventGraph(empty_run(run), config, run.start_time, {0})
    for t, kind, row in rows:
        (live.motion if kind == 0 else live.point)(row)
        emitted.append(live.advance(t))
    emitted.append(live.finish())
    return live


def _same_starts(a: list, b: list) -> None:
    assert len(a) == len(b) > 1
    for x, y in zip(a, b):
        assert x.keys() == y.keys()
        assert all(np.array_equal(x[k].matrix(), y[k].matrix()) for k in x)


@pytest.mark.parametrize("seed", SEEDS)
def test_placed_by_bearings_row_by_row_is_the_whole_run_graph(runs, seed):
    """Rows in time order: the ground robots placed by mutual bearings, the climber resected
    once its three snapshots are in (the run's end): the graph, its placements and the
    climber's P3P alternatives (every candidate: hypotheses) are those of the graph built from
    the whole tables."""
    run, config = open_run(runs / str(seed)), GraphConfig()
    emitted: list = []
    live = _feed(run, config, _rows(run), emitted)
    ref = team_graph(run, config)
    _same_graph(ref, live.graph)
    assert live.graph.anchored_from == ref.anchored_from
    assert live.graph.precision == ref.precision
    _same_starts(ref.alternatives, live.graph.alternatives)
    _same_starts(ref.guessed_alternatives, live.graph.guessed_alternatives)
    # the climber's first snapshot is at the first step: every step waits for its placement
    assert sum(map(len, emitted[:-1])) == 0 and len(emitted[-1]) == len(ref.steps)
    tables = run_tables(run)
    assert route(run, tables) == "event"
    _same_graph(ref, build_live(run, config))  # smooth's and online's route


def _later(run, seconds: float):
    """The run with one more climber step and snapshot `seconds` after its last."""
    last = run.motions[-1]
    t = last.t1 + seconds
    step = Motion(last.robot, last.t1, t, last.relative, last.covariance)
    snapshot = [replace(m, time=t) for m in run.points if m.robot == 0 and m.time == last.t1]
    return replace(run, motions=(*run.motions, step), points=(*run.points, *snapshot))


def test_steps_up_to_the_placement_do_not_change_with_later_rows(runs):
    """Causal: with a fourth snapshot after the run's three, the climber is resected as soon as
    the third is complete -- before the fourth arrives -- and the steps emitted then are the
    three-snapshot run's (the same factors, the same initial values)."""
    run, config = open_run(runs / "1"), GraphConfig()
    short: list = []
    ref = _feed(run, config, _rows(run), short).graph
    longer = _later(run, 1.0)
    rows = _rows(longer)
    fourth = next(i for i, (t, kind, _) in enumerate(rows) if kind == 1 and t > run.motions[-1].t1)
    live = EventGraph(empty_run(longer), config, longer.start_time, {0})
    before = []
    for t, kind, row in rows[:fourth]:  # up to the fourth snapshot's first bearing
        (live.motion if kind == 0 else live.point)(row)
        before += live.advance(t)
    assert [t for t, _ in before] == [t for t, _ in ref.steps]  # all three, before the fourth
    assert live.robots[0].seed is not None and len(live.points.resected[0][0]) > 1
    for (_, a), (_, b) in zip(ref.steps, before):
        assert [factor_keys(f) for f, _ in a] == [factor_keys(f) for f, _ in b]
        assert [f.error(_values(ref.initial)) for f, _ in a] == [
            f.error(_values(ref.initial)) for f, _ in b
        ]
    for key, value in ref.initial.items():
        assert np.array_equal(np.asarray(value.matrix()), live.graph.initial[key].matrix())
    for t, kind, row in rows[fourth:]:
        (live.motion if kind == 0 else live.point)(row)
        live.advance(t)
    live.finish()
    assert len(live.graph.steps) == len(ref.steps) + 1


def _values(initial: dict):
    values = gtsam.Values()
    for key, value in initial.items():
        values.insert(key, value)
    return values


def test_live_team_is_graphloc_online(runs, tmp_path):
    """The log's rows pushed in time order through the live API: one online pass per P3P
    candidate side by side, as `graphloc online` runs them, the same estimates and causal
    estimates; `graphloc live --log-dir` on the finished log writes online's trajectories."""
    source = runs / "3"
    team = replay_live(source)
    result = team.finish()
    online = graphloc.run_team(source, tmp_path / "online", "online").result
    _same_estimates(result, online)
    assert result.hypotheses == online.hypotheses > 2
    assert len(result.survivors) == len(online.survivors)
    out = tmp_path / "live"
    argv = ["live", "--log-dir", str(source), "--out", str(out), "--idle", "2", "--no-progress"]
    assert main(argv) == 0
    for name in [p.name for p in (tmp_path / "online").glob("*_online.tum")]:
        got = np.loadtxt(out / name, ndmin=2)
        want = np.loadtxt(tmp_path / "online" / name, ndmin=2)
        assert got.shape == want.shape and np.abs(got - want).max() < 1e-9, name


def test_without_candidate_sets_the_precision_is_the_steps_before_the_first_step(runs):
    """iSAM2's thresholds of a run without candidate sets come from its relative poses
    (`run_precision`); live, from those that arrived before the first step was emitted: later,
    much finer steps do not change it (the whole run's median would)."""
    run, config = open_run(runs / "1"), GraphConfig()
    fine = np.diag([1e-4] * 3 + [1e-6] * 3)  # 1 mm steps
    longer = run
    for _ in range(3):
        longer = _later(longer, 1.0)
        last = longer.motions[-1]
        longer = replace(longer, motions=(*longer.motions[:-1], replace(last, covariance=fine)))
    live = _feed(longer, config, _rows(longer), [])
    first = longer.motions[: len(run.motions) + 1]  # in when the climber was resected
    assert live.graph.precision == run_precision(replace(run, motions=first))
    assert live.graph.precision > run_precision(longer)


def test_a_team_without_rows_checkpoints_and_finishes_empty(runs, tmp_path):
    """Before any step the passes are not made (the precision comes with the first step): a
    checkpoint then says no step is done, and a team finished without rows has no pose."""
    team = LiveTeam.open(runs / "1", checkpoint=tmp_path / "team.checkpoint")
    team.write_checkpoint()
    assert team.latest("climber") is None
    result = team.finish()
    assert not result.graph.steps and all(np.isnan(e).all() for e in result.estimate)
    assert result.graph.precision == run_precision(replace(open_run(runs / "1"), motions=()))


def test_a_robot_nothing_can_place_is_counted_naming_it(runs):
    """Without its bearings the climber has nothing to place it (no candidate sets, no
    resection): the run is live all the same, and `EventGraph`
    leaves the climber out at `finish` -- a counted `unanchored_robot` naming it, its factors
    out of the graph, no initial value of its poses."""
    run = open_run(runs / "1")
    tables = run_tables(run)
    tables["climber"] = tables["climber"] - {"bearing"}
    climber = [r.name for r in run.robots].index("climber")
    blind = replace(run, points=tuple(p for p in run.points if p.robot != climber))
    graph = build_events(blind, GraphConfig())
    poses = len(graph.node_times[climber])
    assert poses and graph.skips.counts == {"unanchored_robot": poses}
    assert "robot climber: nothing placed it" in "\n".join(graph.skips.examples)
    assert not any(decode(k)[:2] == ("x", climber) for k in graph.initial)
    for _, group in graph.steps:
        for f, _ in group:
            assert all(decode(k)[:2] != ("x", climber) for k in factor_keys(f))
