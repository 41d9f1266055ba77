"""Known landmarks without a variable (issue 15): `known_landmark_factor_3d` is the anchor
(Point3 + prior + range-bearing) marginalized at the measured point, and the team graph ties a
known landmark's range-bearings to the poses by it."""

import importlib

import gtsam
import numpy as np
import pytest
from helpers import write_synthetic_mrclam

from graphloc.datasets import open_run
from graphloc.factors.range_bearing import known_landmark_factor_3d, landmark_factor_3d
from graphloc.factors.robust import Kernel, KernelPolicy
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.runner.team_run import team_graph

team_solve = importlib.import_module("graphloc.pipelines.team_graph.solver")  # the module

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


def test_team_graph_ties_known_landmarks_by_unary_factors(tmp_path):
    """The team graph: a range-bearing to a known landmark is one KnownLandmarkFactorPose3 (no
    landmark variable); the trajectory is the one-shared-variable model's to a few mm (the
    landmark prior's floor lets a shared variable move that little)."""
    write_synthetic_mrclam(tmp_path / "run", duration=20.0)
    run = open_run(tmp_path / "run")
    graph = team_graph(run, GraphConfig())
    shared = team_graph(run, GraphConfig(anchor_known_landmarks=False))
    kinds = [(f, k) for _, group in graph.steps for f, k in group]
    unary = [f for f, k in kinds if k == "landmark"]
    assert unary and all(isinstance(f, gtsam.KnownLandmarkFactorPose3) for f in unary)
    assert graph.counts["landmark_anchors"] == 0
    assert not any(k == "landmark_prior" for _, k in kinds)
    assert len(unary) == sum(k == "landmark" for _, g in shared.steps for _, k in g)
    a, b = solve(graph, "batch"), solve(shared, "batch")
    for r in range(len(run.robots)):
        assert np.nanmax(np.abs(a.estimate[r][:, :3] - b.estimate[r][:, :3])) < 5e-3


def test_batch_starts_lm_from_the_incremental_pass_where_kernels_are_robust(tmp_path, monkeypatch):
    """Robust kernels: LM starts from the incremental pass, at an error no higher than from the
    dead-reckoning guess; no robust kernel: from the guess; a pass iSAM2 cannot solve: from the
    guess, said in `batch_start`."""
    write_synthetic_mrclam(tmp_path / "run", duration=20.0)
    run = open_run(tmp_path / "run")
    graph = team_graph(run, GraphConfig())
    warm = solve(graph, "batch")
    assert warm.batch_start == "incremental pass"
    plain = team_graph(run, GraphConfig(kernels=KernelPolicy()))
    assert solve(plain, "batch").batch_start.startswith("guess (no robust kernel")

    def fails(*args, **kwargs):
        raise ValueError("indeterminate")

    monkeypatch.setattr(team_solve, "warm_starts", fails)
    cold = solve(graph, "batch")
    assert cold.batch_start == (
        "guess and every alternative (the incremental pass failed: indeterminate)"
    )
    assert warm.error <= cold.error * (1 + 1e-6) and np.isfinite(cold.error)
