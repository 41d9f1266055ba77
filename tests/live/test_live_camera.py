"""The camera sections of the event route built as rows arrive (`graphloc.live.event_camera`):
crawler-pair (seed 003) -- a camera's feature tracks and the circle candidate sets of a teammate
without an initial pose (max-mixtures, the teammate placed at its first sighting)."""

from __future__ import annotations

import heapq
import json

import gtsam
import numpy as np
import pytest

import graphloc
from graphloc.datasets import open_run
from graphloc.datasets.scenarios import generate
from graphloc.keys import pose_key
from graphloc.live import LiveTeam, replay_live
from graphloc.live.coverage import route, run_tables
from graphloc.live.setup import empty_run
from graphloc.live.events import EventGraph
from graphloc.pipelines.team_graph import GraphConfig
from graphloc.runner.team_run import team_graph
from helpers_live import _item_error, _same_estimates, _same_graph

SEEDS = (1, 2)


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    root = tmp_path_factory.mktemp("crawler")
    for seed in SEEDS:
        generate("crawler-pair", root / f"s{seed}", seed)
    return {seed: root / f"s{seed}" for seed in SEEDS}


def _rows(run, until=np.inf):
    """The run's relative poses (at their end time), candidate sets and feature pixels up to
    `until`, in time order (`event_rows.build_events`' order)."""
    motions = ((max(m.t0, m.t1), 0, i, m) for i, m in enumerate(run.motions))
    sets = ((o.time, 1, i, o) for i, o in enumerate(run.observations))
    pixels = ((f.time, 2, i, f) for i, f in enumerate(run.features))
    merged = heapq.merge(motions, sets, pixels, key=lambda e: e[:3])
    return [(t, kind, row) for t, kind, _, row in merged if t <= until]


def _live(run, until=np.inf, finish=True, on_steps=lambda steps: None) -> EventGraph:
    stamped = {m.robot for m in run.motions}
    observers = {o.robot for o in run.observations}
    live = EventGraph(empty_run(run), GraphConfig(), run.start_time, stamped, observers, True)
    for t, kind, row in _rows(run, until):
        (live.motion, live.observation, live.feature)[kind](row)
        on_steps(live.advance(t))
    if finish:
        on_steps(live.finish())
        live.graph.run = run
    return live


@pytest.mark.parametrize("seed", SEEDS)
def test_crawler_graph_row_by_row_is_the_graph_of_its_whole_tables(logs, seed):
    """Rows in time order, `advance` after each: the steps come out frame by frame (only the
    last waits for the end) and the graph -- max-mixtures, feature projections and point
    priors, the teammate's initial values from its first sighting -- is the one the verbs
    build from the whole tables (`team_graph`)."""
    run = open_run(logs[seed])
    tables = run_tables(run)
    assert route(run, tables) == "event"
    emitted = []
    live = _live(run, on_steps=emitted.append)
    ref = team_graph(run, GraphConfig())
    _same_graph(ref, live.graph)
    assert len(emitted[-1]) <= 1 < len(ref.steps) == sum(map(len, emitted))
    assert live.graph.anchored_from == ref.anchored_from
    assert [d.status for d in live.graph.decisions] == [d.status for d in ref.decisions]
    assert {k: v[0] for k, v in live.graph.links.items()} == {k: v[0] for k, v in ref.links.items()}
    assert ref.counts["feature_tracks"] > 0 and ref.counts["factors_candidate"] > 0
    assert live.graph.camera and ref.camera


def test_steps_up_to_a_time_do_not_change_with_later_rows(logs):
    """Causality: the rows up to time T alone give the steps the whole run gives up to the
    last one they complete -- the same factors on the same variables, with the same errors --
    and the same initial values of their variables."""
    run = open_run(logs[1])
    full = _live(run).graph
    values = gtsam.Values()
    for key, value in full.initial.items():
        values.insert(key, value)
    for until in (2.0, 7.0, 11.0):
        part = _live(run, until, finish=False).graph
        assert 0 < len(part.steps) < len(full.steps)
        assert part.steps[-1][0] <= until
        for (t, group), (t_full, group_full) in zip(part.steps, full.steps):
            assert t == t_full
            assert [kind for _, kind in group] == [kind for _, kind in group_full]
            assert [_item_error(f, values) for f, _ in group] == [
                _item_error(f, values) for f, _ in group_full
            ]
        keys = {k for _, group in part.steps for f, _ in group for k in _keys(f)}
        for key in keys:
            a, b = part.initial[key], full.initial[key]
            assert np.array_equal(_array(a), _array(b))


def _keys(item) -> list:
    from graphloc.pipelines.team_graph.graph import factor_keys

    return factor_keys(item)


def _array(value) -> np.ndarray:
    return value.matrix() if isinstance(value, gtsam.Pose3) else np.asarray(value)


def test_live_team_is_graphloc_online(logs, tmp_path):
    """The log's rows pushed in time order through the live API: every step one update, the
    estimates and causal estimates of `run_team(..., "online")` (which builds the same graph
    with the same builder); the teammate gets no pose before the sighting that places it."""
    updates = []
    team = replay_live(logs[1], subscriber=updates.append)
    result = team.finish()
    online = graphloc.run_team(logs[1], tmp_path / "out", "online").result
    _same_estimates(result, online)
    assert [u.step for u in updates] == list(range(len(result.graph.steps)))
    seen = [u.time for u in updates if "teammate" in u.poses]
    assert seen and min(seen) == result.graph.anchored_from[1]
    assert not team.skips.counts


def test_bad_camera_rows_are_counted_naming_robot_table_row_and_field(logs):
    """Rows of the camera tables are checked as a log's: a bad one is a counted skip naming
    robot, table, row and field, never a traceback."""
    team = LiveTeam.open(logs[1])
    ellipse = {
        "time": 0.0,
        "sensor": "cam",
        "target": "teammate",
        "u0": 320.0,
        "v0": 240.0,
        "width": 30.0,
        "height": 31.0,
        "angle": 10.0,
        "centre_sigma": 0.03,
        "radius_sigma": 0.007,
    }
    team.push("camera", "ellipses", {**ellipse, "width": "nan"})  # row 1
    team.push("camera", "ellipses", {**ellipse, "target": "nobody"})  # row 2
    team.push("camera", "ellipses", {**ellipse, "target": "camera"})  # row 3
    team.push("camera", "ellipses", {**ellipse, "width": 0.0})  # row 4: no circle's image
    pixel = {"time": 0.0, "sensor": "cam", "track": 3, "u": 100.0, "v": 120.0}
    team.push("camera", "features", {**pixel, "u": "x"})  # row 5
    team.push("camera", "features", {k: v for k, v in pixel.items() if k != "v"})  # row 6
    team.push("camera", "features", pixel)  # rows 7, 8: one track twice in one image
    team.push("camera", "features", {**pixel, "u": 101.0})
    team.finish()
    counts = team.skips.counts
    assert counts.get("non_finite") == 1 and counts.get("parse") == 1
    assert counts.get("unknown_target") == 2 and counts.get("missing_field") == 1
    assert counts.get("not_a_circle") == 1 and counts.get("duplicate_track") == 2
    examples = "\n".join(team.skips.examples)
    for text in (
        "robot 'camera', table 'ellipses', row 1: field 'width'",
        "robot 'camera', table 'ellipses', row 3: field 'target'",
        "robot 'camera', table 'ellipses', row 4: fields 'u0 .. radius_sigma'",
        "robot 'camera', table 'features', row 5: field 'u'",
        "robot 'camera', table 'features', row 6: field 'v'",
        "robot 'camera', table 'features', row 7: field 'track'",
    ):
        assert text in examples, text


def test_rows_of_a_camera_nothing_places_are_counted_naming_robot_and_table(logs, tmp_path):
    """A camera without an initial pose that nothing places (no candidate sets of a placed
    target): no refusal -- its feature pixels and circle sets wait for a placement that never
    comes, counted `unplaced_camera` naming robot and table, both robots `unanchored_robot`;
    the live team, `team_graph` and `run_team(..., "online")` give the same counts and no
    pose."""
    source = tmp_path / "run"
    source.mkdir()
    for path in logs[1].iterdir():
        (source / path.name).write_bytes(path.read_bytes())
    manifest = json.loads((source / "manifest.json").read_text())
    del manifest["robots"][0]["initial_pose"]
    (source / "manifest.json").write_text(json.dumps(manifest))
    run = open_run(source)
    assert route(run, run_tables(run)) == "event"
    team = replay_live(source)
    result = team.finish()
    graph = team_graph(run, GraphConfig())
    pixels, sets = len(run.features), len(run.observations)
    counts = {"unplaced_camera": pixels + sets, "unanchored_robot": sum(map(len, graph.node_times))}
    assert team.skips.counts == graph.skips.counts == counts
    examples = "\n".join(graph.skips.examples)
    for text in (
        f"robot camera: table 'features': {pixels} pixels",
        f"robot camera: table 'ellipses': {sets} circle sets of teammate",
        "robot camera: nothing placed it",
        "robot teammate: nothing placed it",
    ):
        assert text in examples, text
    assert pose_key(0, 0) not in graph.initial and pose_key(1, 0) not in graph.initial
    assert not any(group for _, group in graph.steps)  # every factor touches an unplaced pose
    online = graphloc.run_team(source, tmp_path / "out", "online")
    _same_estimates(result, online.result)
    assert all(np.isnan(e).all() for e in result.estimate)
    assert online.metrics["skipped"]["counts"] == counts
