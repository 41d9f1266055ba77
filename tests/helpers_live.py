"""What the live tests compare with (tests/live/): the graph and the estimates of the live
route against the whole-table ones, rows fed in random chunks, and an `EventGraph` fed a
run's rows one by one."""

from __future__ import annotations

import heapq

import gtsam
import numpy as np

from graphloc.factors.mixture import MaxMixture
from graphloc.live.events import EventGraph
from graphloc.live.setup import empty_run
from graphloc.pipelines.team_graph.graph import factor_keys


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
            assert np.array_equal(np.asarray(value), np.asarray(other), equal_nan=True)
        values.insert(key, value)
    errors = [_item_error(f, values) for _, group in ref.steps for f, _ in group]
    assert np.isfinite(errors).all()
    assert errors == [_item_error(f, values) for _, group in graph.steps for f, _ in group]
    assert ref.counts == graph.counts
    assert ref.skips.counts == graph.skips.counts


def _item_error(item, values) -> float:
    """A graph item's error: a gtsam factor's, or a max-mixture's per component (a sum that
    differs when any component does)."""
    if isinstance(item, MaxMixture):
        errors = item.component_errors(values)
        return float(np.sum(errors * np.arange(1, len(errors) + 1)))
    return item.error(values)


def _fed_in_chunks(run, config, seed: int):
    """`LiveGraph` fed the run's rows in time order in random chunks (one row to a few dozen,
    odometry and measurements as they interleave), `advance` after each chunk; seed None: one
    row at a time."""
    from graphloc.live.builder import LiveGraph

    rng = np.random.default_rng(seed)
    rows = [(row[0], 0, r, row) for r, v in enumerate(run.velocity) for row in v]
    rows += [(m.time, 1, i, m) for i, m in enumerate(run.points)]
    rows.sort(key=lambda e: (e[0], e[1], e[2]))
    live = LiveGraph(empty_run(run), config, run.start_time)
    i = 0
    while i < len(rows):
        j = min(len(rows), i + (1 if seed is None else int(rng.choice([1, 1, 1, 2, 7, 40]))))
        for _, kind, r, item in rows[i:j]:
            live.velocity(r, item) if kind == 0 else live.point(item)
        live.advance(rows[j - 1][0])
        i = j
    live.finish()
    return live.graph


def _same_estimates(result, reference, tol: float = 1e-9) -> None:
    assert len(result.estimate) == len(reference.estimate)
    for name in ("estimate", "causal"):
        for a, b in zip(getattr(result, name), getattr(reference, name)):
            assert a.shape == b.shape
            assert np.array_equal(np.isnan(a), np.isnan(b))
            assert np.nanmax(np.abs(a - b), initial=0.0) <= tol


def _rows(run):
    """The run's relative poses (at their end time) and candidate sets, in time order."""
    motions = ((max(m.t0, m.t1), 0, i, m) for i, m in enumerate(run.motions))
    sets = ((o.time, 1, i, o) for i, o in enumerate(run.observations))
    return [(t, kind, row) for t, kind, _, row in heapq.merge(motions, sets, key=lambda e: e[:3])]


def _event_graph(run, config) -> EventGraph:
    """An empty `EventGraph` of the run's robots (its tables: relative poses, candidate sets)."""
    stamped, observers = {m.robot for m in run.motions}, {o.robot for o in run.observations}
    return EventGraph(empty_run(run), config, run.start_time, stamped, observers)


def _live(run, config, on_steps=lambda steps: None) -> EventGraph:
    live = _event_graph(run, config)
    for t, kind, row in _rows(run):
        (live.motion if kind == 0 else live.observation)(row)
        on_steps(live.advance(t))
    on_steps(live.finish())
    return live
