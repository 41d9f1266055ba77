"""`team_graph.graph`'s steps after the sections: initial values from the placed poses, and
factors grouped in time steps with those touching an unplaced variable left out."""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.keys import landmark_key, pose_key
from graphloc.pipelines.team_graph.graph import initial_values, time_steps


def _prior(key) -> gtsam.PriorFactorPose3:
    return gtsam.PriorFactorPose3(key, gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 1.0))


def test_initial_values_place_landmarks_from_placed_poses_only():
    at = gtsam.Pose3(gtsam.Rot3(), np.array([1.0, 2.0, 0.0]))
    poses = {0: ([at, at], 0)}  # robot 1 is not placed
    guesses = {
        landmark_key(0): ("from", 0, 1, np.array([1.0, 0.0, 0.0]), 2.0),
        landmark_key(1): ("from", 1, 0, np.array([1.0, 0.0, 0.0]), 2.0),
        landmark_key(2): (5.0, 5.0, 0.0),
    }
    initial = initial_values(poses, guesses, {}, [])
    assert set(initial) == {pose_key(0, 0), pose_key(0, 1), landmark_key(0), landmark_key(2)}
    assert np.allclose(initial[landmark_key(0)], [3.0, 2.0, 0.0])


def test_time_steps_group_by_time_and_drop_factors_on_unplaced_poses():
    initial = {pose_key(0, 0): gtsam.Pose3(), pose_key(0, 1): gtsam.Pose3()}
    factors = [
        (1.0, _prior(pose_key(0, 1)), "prior"),
        (0.0, _prior(pose_key(0, 0)), "prior"),
        (1.0, _prior(pose_key(1, 0)), "prior"),  # robot 1 has no initial value
        (1.0, _prior(pose_key(0, 1)), "candidate"),
    ]
    steps, types, dropped = time_steps(factors, initial)
    assert [t for t, _ in steps] == [0.0, 1.0] and [len(g) for _, g in steps] == [1, 2]
    assert types == ["prior", "prior", "candidate"] and dropped == 1
