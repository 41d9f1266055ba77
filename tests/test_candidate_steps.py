"""The team graph's candidate section in its three steps (issue 49): decide a stream's sets ->
the factors of the decisions -> place the observers, each with explicit inputs and outputs."""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.datasets import open_run
from graphloc.datasets.scenarios import generate
from graphloc.pipelines.team_graph.candidates import (
    StreamDecisions,
    TrackedSet,
    candidate_section,
    place_observers,
)
from graphloc.pipelines.team_graph.config import GraphConfig
from graphloc.pipelines.team_graph.motion import Timeline, motion_factors
from graphloc.seams import Decision

BODIES = [gtsam.Pose3(gtsam.Rot3(), np.array([float(i), 0.0, 0.0])) for i in range(2)]


def _set(k: int, committed: int, probabilities: list, decided: bool) -> TrackedSet:
    update = Decision(np.array(probabilities), committed, committed >= 0, None)
    return TrackedSet(k, None, k, k, [], np.zeros((2, 6, 6)), BODIES, None, update, decided)


def test_a_pixel_stream_places_its_observer_once_at_its_first_decided_set():
    sets = [_set(2, -1, [0.4, 0.6], False), _set(3, 1, [0.0, 1.0], True), _set(4, 0, [1, 0], True)]
    decided, _, alternatives = place_observers([StreamDecisions(0, 1, True, sets)])
    assert list(decided) == [0] and list(decided[0]) == [3] and decided[0][3] is BODIES[1]
    starts, guessed = alternatives[0]
    assert [k for k, _ in starts] == [2, 2] and [b for _, b in starts] == BODIES
    assert guessed is False


def test_a_pixel_stream_never_decided_is_placed_by_its_first_sets_guess():
    stream = StreamDecisions(0, 1, True, [_set(2, -1, [0.4, 0.6], False)])
    decided, _, alternatives = place_observers([stream])
    assert decided[0] == {2: BODIES[1]} and alternatives[0][1] is True


def test_without_pixels_every_decided_set_places_and_no_alternatives():
    sets = [_set(2, 0, [1.0, 0.0], True), _set(3, -1, [0.5, 0.5], False), _set(4, 1, [0, 1], True)]
    decided, _, alternatives = place_observers([StreamDecisions(0, 1, False, sets)])
    assert decided[0] == {2: BODIES[0], 4: BODIES[1]} and alternatives == {}


def test_the_section_returns_what_it_makes_and_leaves_the_run_as_it_was(tmp_path):
    generate("kaushik-p3p-error", tmp_path / "log", seed=5)
    run = open_run(tmp_path / "log")
    config = GraphConfig()
    timeline = Timeline(run, config)
    step_rel = motion_factors(run, config, timeline).step_rel
    section = candidate_section(run, config, timeline, step_rel)
    again = candidate_section(run, config, timeline, step_rel)
    assert len(section.decisions) > 0 and len(section.factors) == len(again.factors)
    skipped = section.skips.counts.get("no_pose_at_time", 0)
    assert len(section.decisions) + skipped == len(run.observations)
    kinds = {kind for _, _, kind in section.factors}
    assert kinds <= {"candidate", "marker", "marker_prior", "marker_layout"} and kinds
    assert set(section.decided_pose) | set(section.placed_via) <= set(range(len(run.robots)))
