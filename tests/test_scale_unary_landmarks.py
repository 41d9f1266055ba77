"""Known landmarks without a variable (issue 15, what-if of scripts/bench_scale.py):
`known_landmark_factor_3d` is the anchor (Point3 + prior + range-bearing) marginalized at the
measured point, and `known_landmarks_unary` folds every anchor of a team graph into one."""

import gtsam
import numpy as np
import pytest
from test_mrclam import write_synthetic_mrclam

from graphloc.datasets import open_run
from graphloc.experiments.scale import known_landmarks_unary
from graphloc.factors.range_bearing import known_landmark_factor_3d, landmark_factor_3d
from graphloc.factors.robust import Kernel
from graphloc.pipelines.team_graph import GraphConfig, build_graph, solve

SIGMAS = (0.02, 0.02, 0.1)


def _anchor_error(pose, landmark, sigma, direction, rng):
    """min over the anchor of (range-bearing + prior) error, the pose held (what the unary
    factor stands for)."""
    graph = gtsam.NonlinearFactorGraph()
    graph.add(landmark_factor_3d(0, 1, direction, rng, SIGMAS))
    graph.add(gtsam.PriorFactorPoint3(1, landmark, gtsam.noiseModel.Isotropic.Sigma(3, sigma)))
    graph.add(gtsam.PriorFactorPose3(0, pose, gtsam.noiseModel.Isotropic.Sigma(6, 1e-9)))
    values = gtsam.Values()
    values.insert(0, pose)
    values.insert(1, landmark)
    result = gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()
    return graph.at(0).error(result) + graph.at(1).error(result)


def test_unary_factor_matches_the_marginalized_anchor():
    rng = np.random.default_rng(3)
    landmark = np.array([4.0, 1.0, 0.0])
    for _ in range(5):
        true = gtsam.Pose3(gtsam.Rot3.Yaw(rng.uniform(-3, 3)), rng.uniform(-1, 1, 3) * [1, 1, 0])
        local = true.transformTo(landmark)
        direction, r = local / np.linalg.norm(local), float(np.linalg.norm(local))
        pose = true.retract(rng.normal(0, 0.03, 6) * [0, 0, 1, 1, 1, 0])  # a few cm / deg off
        factor = known_landmark_factor_3d(7, landmark, 0.01, direction, r, SIGMAS)
        values = gtsam.Values()
        values.insert(7, pose)
        assert factor.keys() == [7]
        expected = _anchor_error(pose, landmark, 0.01, direction, r)
        assert factor.error(values) == pytest.approx(expected, rel=0.05, abs=1e-3)
        values.update(7, true)
        assert factor.error(values) < 1e-12  # zero at the pose that measured it
    robust = known_landmark_factor_3d(7, landmark, 0.01, [1, 0, 0], 2.0, SIGMAS, Kernel("cauchy"))
    assert isinstance(robust.noiseModel(), gtsam.noiseModel.Robust)
    with pytest.raises(ValueError, match="landmark sigma"):
        known_landmark_factor_3d(7, landmark, float("nan"), [1, 0, 0], 2.0, SIGMAS)
    with pytest.raises(ValueError, match="non-positive range"):
        known_landmark_factor_3d(7, landmark, 0.01, [1, 0, 0], 0.0, SIGMAS)


def test_team_graph_without_anchors_solves_to_the_same_trajectory(tmp_path):
    write_synthetic_mrclam(tmp_path / "run", duration=20.0)
    run = open_run(tmp_path / "run")
    graph = build_graph(run, GraphConfig())
    folded = known_landmarks_unary(graph)
    anchors = graph.counts["landmark_anchors"]
    assert anchors > 0 and folded.counts["landmark_anchors_folded"] == anchors
    assert len(folded.initial) == len(graph.initial) - anchors
    kinds = [k for _, group in folded.steps for _, k in group]
    assert "landmark_prior" not in kinds and kinds.count("landmark") == anchors
    assert folded.factor_types == kinds
    a, b = solve(graph, "batch"), solve(folded, "batch")
    for r in range(len(run.robots)):  # same model to first order: same trajectory to ~mm
        assert np.nanmax(np.abs(a.estimate[r][:, :3] - b.estimate[r][:, :3])) < 1e-3
