"""Seed 000 Table I (000_05137a0a9c449be3.txt, Sec. VI-A) through the front door: a climber
resected by P3P from three snapshots has alternatives from each snapshot's candidates
(`live.event_points`), each carried to every pose of the climber. The hypotheses pass
(`team_graph.solver.hypotheses`) must not drop an alternative of a later snapshot on the steps
before its snapshot: there its start is that later snapshot's position, not evidence against
it. Trial 5 of the table's config (seed 0) is one whose only genuine start is the third
snapshot's candidate (the first snapshot's genuine candidate sits in a pseudo solution's
basin, Sec. IV); it went to a wrong basin when every step judged every hypothesis."""

import tempfile
from pathlib import Path

import numpy as np

from benchmarks.front_door import table_i_trial
from benchmarks.seed000_table1 import trial_rows
from graphloc.datasets import open_run
from graphloc.datasets.feng_deterministic import (
    Seed000Config,
    TableIConfig,
    ground_triangle,
    simulate_straight_line_trials,
)
from graphloc.datasets.formation_log import write_table_i_trial
from graphloc.live.builder import build_live
from graphloc.pipelines.team_graph import GraphConfig
from graphloc.runner.team_run import team_graph
from graphloc.pipelines.team_graph.side_by_side import start_times

TRIAL = 5  # a Table I trial index (of the default TableIConfig's trials)


def _table_i_trial(index: int):
    """Trial `index` of Table I as `seed000_table1.table_i` draws them (the whole pool: its
    draws are batched, so a smaller pool is other trials)."""
    config = TableIConfig()
    sim = Seed000Config(
        pixel_sigma=config.pixel_sigma,
        lateral_sigma=config.lateral_sigma,
        orientation=config.orientation,
    )
    pool = simulate_straight_line_trials(int(1.1 * config.trials) + 10, config.seed, sim)
    tri = ground_triangle(pool.ground, config, np.random.default_rng([config.seed, 1]))
    row = np.flatnonzero(tri.visible)[: config.trials][[index]]
    return trial_rows(pool, row), trial_rows(tri, row), config, 3 * sim.step_mean


def judged_from(graph, alternatives: list, times: list) -> list | None:
    """Per start (the guess, then `alternatives` placed at node times `times`), the first of
    `graph.steps` at which `SideBySide` may drop it: the step of its own node (0 for the guess);
    None where `start_times` is."""
    starts = start_times(alternatives, times)
    if starts is None:
        return None
    step_times = np.array([t for t, _ in graph.steps])
    return [0 if t is None else int(np.searchsorted(step_times, t - 1e-9)) for t in starts]


def _judged(graph, alternatives: list, times: list) -> list:
    judged = judged_from(graph, alternatives, times)
    assert judged is not None and len(judged) == len(alternatives) + 1 and judged[0] == 0
    assert all(0 <= j < len(graph.steps) for j in judged)
    return judged


def test_later_snapshot_alternative_is_judged_from_its_own_step():
    trials, tri, config, step_sigma = _table_i_trial(TRIAL)
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = Path(tmp) / "run"
        write_table_i_trial(
            trials, tri, 0, config.pixel_sigma, step_sigma, "seed000-table1", run_dir
        )
        run = open_run(run_dir)
        graph = team_graph(run, GraphConfig())
        live = build_live(run, GraphConfig())
    # one alternative per candidate of each of the three snapshots: judged at its own step
    judged = _judged(graph, graph.alternatives, graph.alternative_times)
    assert sorted(set(judged[1:])) == [0, 1, 2]
    # the live event route (smooth, online, live): the resected climber's variants alike,
    # among every alternative and among the guessed ones the online solve runs
    judged = _judged(live, live.alternatives, live.alternative_times)
    assert sorted(set(judged[1:])) == [0, 1, 2]
    judged = _judged(live, live.guessed_alternatives, live.guessed_alternative_times)
    assert sorted(set(judged[1:])) == [0, 1, 2]


def test_table_i_trial_resolved_by_a_later_snapshot_candidate():
    trials, tri, config, step_sigma = _table_i_trial(TRIAL)
    climber, ground, error, _ = table_i_trial((trials, tri, config.pixel_sigma, step_sigma))
    err = np.linalg.norm(climber - trials.positions[0], axis=1)
    assert np.isfinite(error)
    assert (err < config.success_tol).all(), err
