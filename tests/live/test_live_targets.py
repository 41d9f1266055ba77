"""The event route's candidate streams beyond one observer's sets of one placed target
(`graphloc.live.event_sets`), on feng-probabilistic runs edited by `target_streams`: a target
without an initial pose seen by a placed observer (max-mixtures), a moving target's sets
without marker pixels (between factors on both poses), one observer's sets of two targets and
of one target with and without pixels (streams; the first that places the observer places
it). Each is live, causal (the steps up to a time do not change
when later rows exist) and its graph built row by row the one built from the whole tables."""

from __future__ import annotations

import json
from dataclasses import replace

import gtsam
import numpy as np
import pytest

from graphloc.datasets import open_run
from graphloc.datasets.scenarios import generate
from graphloc.keys import decode
from graphloc import run_team
from graphloc.live import replay_live
from graphloc.live.builder import build_live
from graphloc.live.event_rows import build_events
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.pipelines.report import evaluate
from graphloc.pipelines.team_graph.graph import factor_keys
from target_streams import CASES, write_moving_target, write_two_targets
from helpers_live import _live, _same_estimates, _same_graph


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    source = tmp_path_factory.mktemp("targets") / "feng"
    generate("feng-probabilistic", source, 1)
    return open_run(source)


def _live_and_whole(run):
    """The run's graph built row by row (`advance` after each) and from the whole tables
    (`build_live`, what the verbs solve)."""
    emitted: list = []  # `advance` after each row: the live order
    return build_events(run, GraphConfig(), emitted), build_live(run, GraphConfig())


def _placing(events) -> int:
    """The climber's node its streams place it at: each stream's first decided set, or a pixel
    stream's `guess_after_sets`-th set (`live.event_sets`); the earliest of them."""
    wait, nodes = GraphConfig().guess_after_sets, []
    for tracker, _, _ in events.streams.values():
        out = tracker.out
        for i, s in enumerate(out.sets):
            if s.decided or (out.pixel_route and i + 1 >= wait):
                nodes.append(s.k)
                break
    return min(nodes)


def test_a_placed_observer_places_an_unplaced_target_by_max_mixtures(base):
    """The climber at its true start, the ground robot without an initial pose: every set a
    max-mixture between their poses, the target placed at the first set through the climber
    (its upright candidate); row by row and whole, one graph, one online estimate."""
    run = CASES["placed-observer"](base)
    live, whole = _live_and_whole(run)
    _same_graph(whole, live)
    assert live.camera and whole.camera  # iSAM2's settings for max-mixtures, known at open
    assert [d.mixture is not None for d in live.decisions] == [True] * len(run.observations)
    assert live.anchored_from[1] == run.observations[0].time
    _same_estimates(solve(live, "online"), solve(whole, "online"))


def test_a_moving_targets_sets_without_pixels_are_between_factors(base):
    """The ground robot drives, the climber's sets of it carry no pixels: each decided set is
    a robust between factor on the climber's and the ground robot's poses at the set, made
    when the set is decided; row by row and whole, one graph and online estimate."""
    run = CASES["moving-target"](base)
    live, whole = _live_and_whole(run)
    _same_graph(whole, live)
    candidates = [f for _, group in live.steps for f, kind in group if kind == "candidate"]
    decided = [d for d in live.decisions if d.status == "decided"]
    assert len(candidates) == len(decided) > 0
    for f, d in zip(candidates, decided):
        assert isinstance(f, gtsam.BetweenFactorPose3)
        (a, k), (b, kt) = (decode(key)[1:] for key in factor_keys(f))
        assert (a, b) == (0, 1)
        tol = GraphConfig().sync_tolerance  # the poses nearest the set
        assert abs(live.node_times[0][k] - d.time) <= tol >= abs(live.node_times[1][kt] - d.time)
    _same_estimates(solve(live, "online"), solve(whole, "online"))


def test_an_observers_sets_of_two_targets_are_two_streams(base):
    """Every other set of the climber is of a second static target: two streams, the climber
    placed by the first that decides (its first decided set of either), the other's factors
    with it; row by row and whole, one graph."""
    run = CASES["two-targets"](base)
    live, whole = _live_and_whole(run)
    _same_graph(whole, live)
    events = _live(run, GraphConfig())
    assert list(events.streams) == [(0, 1, True), (0, 2, True)]
    assert live.anchored_from[0] == live.node_times[0][_placing(events)]
    assert {d.target for d in live.decisions} == {1, 2}


def test_sets_with_and_without_pixels_are_two_streams(base):
    """Every other set without its pixels: the pixel sets are one stream (projection factors),
    the others another (decided sets: robust priors); the first that places the climber
    places it: consistent, the climber's ATE within a quarter of the run whose sets all carry
    their pixels (one stream)."""
    run = CASES["mixed-pixels"](base)
    live, whole = _live_and_whole(run)
    events = _live(run, GraphConfig())
    assert list(events.streams) == [(0, 1, True), (0, 1, False)]
    types = set(live.factor_types)
    assert {"marker", "candidate"} <= types
    assert live.anchored_from[0] == live.node_times[0][_placing(events)]
    _same_graph(whole, live)
    pixels = build_live(base, GraphConfig())
    for mode in ("batch", "online"):
        a, b = evaluate(solve(live, mode), run), evaluate(solve(pixels, mode), base)
        assert a["consistent"] and b["consistent"]
        ate = [m["per_robot"]["climber"][mode]["ate_rmse"] for m in (a, b)]
        assert ate[0] <= 1.25 * ate[1]


@pytest.mark.parametrize(
    "case", ["placed-observer", "moving-target", "two-targets", "mixed-pixels"]
)
def test_the_steps_up_to_a_time_do_not_change_when_later_rows_exist(base, case):
    """Causal: the run cut at a time (every row after it withheld) emits before its end the
    same steps -- times, factors, initial values of their keys -- as the whole run does."""
    run, config = CASES[case](base), GraphConfig()
    whole = build_events(run, config)
    times = sorted(o.time for o in run.observations)
    for cut in (times[len(times) // 3], times[2 * len(times) // 3]):
        part = replace(
            run,
            motions=tuple(m for m in run.motions if max(m.t0, m.t1) <= cut),
            observations=tuple(o for o in run.observations if o.time <= cut),
        )
        emitted: list = []
        live = build_events(part, config, emitted)
        early = [step for steps in emitted[:-1] for step in steps]  # before `finish`
        assert early and len(early) < len(whole.steps)
        assert [t for t, _ in early] == [t for t, _ in whole.steps[: len(early)]]
        for (_, fa), (_, fb) in zip(early, whole.steps):
            assert [factor_keys(f) for f, _ in fa] == [factor_keys(f) for f, _ in fb]
        for key in {k for _, group in early for f, _ in group for k in factor_keys(f)}:
            if key not in live.initial:  # a robot not placed by the cut: held
                continue
            a, b = live.initial[key], whole.initial[key]
            a, b = (a.matrix(), b.matrix()) if isinstance(a, gtsam.Pose3) else (a, b)
            assert np.array_equal(np.asarray(a), np.asarray(b))


def test_live_team_on_a_placed_observers_log_is_graphloc_online(tmp_path):
    """The placed-observer case written as a log (the climber's `initial_pose` its true start,
    the ground robot's removed, its floor and attitude in the manifest): pushed row by row
    through the live API it gives `run_team(..., "online")`'s estimates -- the graph a
    max-mixture camera graph from the team's opening on, every set a max-mixture."""
    source = tmp_path / "run"
    generate("feng-probabilistic", source, 1)
    manifest = json.loads((source / "manifest.json").read_text())
    start = open_run(source).groundtruth[0][1][0]
    q = start.rotation().toQuaternion()
    climber, ground = manifest["robots"]
    climber["initial_pose"] = [*start.translation(), q.x(), q.y(), q.z(), q.w()]
    del ground["initial_pose"]
    floor = {"point": [0, 0, 0], "normal": [0, 0, 1], "attitude_sigma": 0.05}
    ground["surface"] = floor
    (source / "manifest.json").write_text(json.dumps(manifest))
    team = replay_live(source)
    assert team.graph.camera
    result = team.finish()
    online = run_team(source, tmp_path / "out", "online").result
    _same_estimates(result, online)
    assert online.hypotheses == 1 and not team.skips.counts
    mixtures = [d for d in result.graph.decisions if d.mixture is not None]
    assert len(mixtures) == len(open_run(source).observations) > 0
    assert np.isfinite(result.estimate[1]).all()


def _pushed_is_online(tmp_path, write):
    """feng-probabilistic seed 1 rewritten by `write` as a log, pushed row by row through the
    live API: the live team's result, checked equal to `run_team(..., "online")`'s estimates
    and causal estimates (one hypothesis, no skips). Returns (log directory, live result)."""
    feng = tmp_path / "feng"
    generate("feng-probabilistic", feng, 1)
    source = write(feng, tmp_path / "run")
    team = replay_live(source)
    result = team.finish()
    online = run_team(source, tmp_path / "out", "online").result
    _same_estimates(result, online)
    assert online.hypotheses == 1 and not team.skips.counts
    return source, result


def test_live_team_on_a_moving_targets_candidates_log_is_graphloc_online(tmp_path):
    """The moving-target case written as a log (`candidates` rows, both robots'
    `relative_pose3`): pushed row by row through the live API it gives `run_team(...,
    "online")`'s estimates and causal estimates; both robots estimated, the sets' decisions
    between factors (`smooth` builds the same graph from the whole tables)."""
    source, result = _pushed_is_online(tmp_path, write_moving_target)
    assert all(np.isfinite(e).all() for e in result.estimate)
    run = open_run(source)
    _same_graph(result.graph, build_live(run, GraphConfig()))
    assert result.graph.counts["factors_candidate"] > 0


def test_live_team_on_a_log_of_two_targets_is_graphloc_online(tmp_path):
    """Every other image of the climber sees a second static robot (its markers in its own
    frame, `write_two_targets`): pushed row by row through the live API, the two streams give
    `run_team(..., "online")`'s estimates and causal estimates, and the graph `smooth` builds
    from the whole tables."""
    source, result = _pushed_is_online(tmp_path, write_two_targets)
    assert {d.target for d in result.graph.decisions} == {1, 2}
    assert np.isfinite(result.estimate[0]).all()
    run = open_run(source)
    _same_graph(result.graph, build_live(run, GraphConfig()))
