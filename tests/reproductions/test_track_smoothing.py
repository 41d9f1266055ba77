"""benchmarks.track_smoothing: the one builder of a track with decided candidates
(seed 000 Sec. V decisions of the tracker; seed 004 Table 1's genuine candidates)."""

import gtsam
import numpy as np
import pytest

from graphloc.candidates import CandidateSet
from graphloc.factors.robust import Kernel
from graphloc.keys import pose_key
from benchmarks.track_smoothing import decided, smooth_track, track_graph
from graphloc.seams import Decision, Odometry


def _track():
    truth = [gtsam.Pose3(gtsam.Rot3.Yaw(0.1 * k), np.array([0.5 * k, 0.0, 2.0])) for k in range(3)]
    odo = [None] + [Odometry(truth[k - 1].between(truth[k]), np.eye(6) * 1e-4) for k in (1, 2)]
    cands = []
    for k, pose in enumerate(truth):
        false = gtsam.Pose3(gtsam.Rot3.Roll(0.3), pose.translation() + np.array([0.0, 0.4, 0.0]))
        R = np.stack([false.rotation().matrix(), pose.rotation().matrix()])
        t = np.stack([false.translation(), pose.translation()])
        cands.append(
            CandidateSet(
                R, t, np.ones(2), time=float(k), covariance=np.stack([np.eye(6) * 1e-4] * 2)
            )
        )
    return truth, odo, cands


def test_initial_values_chain_from_the_first_choice_and_priors_are_the_chosen_candidates():
    truth, odo, cands = _track()
    graph, values = track_graph(cands, odo, [-1, 1, 1], kernel=Kernel())
    assert graph.size() == 2 + 2  # two odometry steps, two chosen candidates
    for k in range(3):  # the first chosen candidate is the truth, the odometry is exact
        assert values.atPose3(pose_key(0, k)).equals(truth[k], 1e-9)
    priors = [
        graph.at(i) for i in range(graph.size()) if isinstance(graph.at(i), gtsam.PriorFactorPose3)
    ]
    assert len(priors) == 2 and all(
        p.prior().equals(truth[k], 1e-9) for p, k in zip(priors, (1, 2))
    )
    assert not isinstance(priors[0].noiseModel(), gtsam.noiseModel.Robust)
    robust, _ = track_graph(cands, odo, [-1, 1, 1])
    assert isinstance(robust.at(robust.size() - 1).noiseModel(), gtsam.noiseModel.Robust)


def test_decisions_and_smoothing():
    truth, odo, cands = _track()
    decisions = [
        Decision(np.array([0.5, 0.5]), -1, False, None),
        Decision(np.array([0.0, 1.0]), 1, True, truth[1]),
        Decision(np.array([0.0, 1.0]), 1, True, truth[2]),
    ]
    chosen, initial = decided(decisions)
    assert chosen == [-1, 1, 1] and initial[0] is None and initial[2] is truth[2]
    centres = smooth_track(cands, odo, chosen)
    np.testing.assert_allclose(centres, np.stack([p.translation() for p in truth]), atol=1e-6)


def test_bad_inputs():
    _, odo, cands = _track()
    with pytest.raises(ValueError, match="no frame"):
        track_graph(cands, odo, [-1, -1, -1])
    with pytest.raises(ValueError, match="must match"):
        track_graph(cands, odo[:2], [0, 0, 0])
    with pytest.raises(ValueError, match="Odometry"):
        track_graph(cands, [None, None, odo[2]], [0, 0, 0])
