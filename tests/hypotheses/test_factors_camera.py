"""Camera-side factors: inter-robot bearing (CustomFactor), range / known baseline, P3P
candidate mixture (HybridNonlinearFactor), surface constraint."""

import gtsam
import numpy as np
import pytest

from graphloc.candidates import CandidateSet
from graphloc.factors.bearing import bearing_factor, range_factor
from graphloc.factors.mixture import candidate_covariances, component_factors
from graphloc.factors.surface import SurfacePlane, plane_attitude_factor, plane_distance_factor
from benchmarks.bearing_cost import predicted_bearing
from benchmarks.candidate_mixtures import candidate_mixture
from graphloc.keys import mode_key, pose_key


def pose(ypr, t):
    return gtsam.Pose3(gtsam.Rot3.Ypr(*ypr), np.asarray(t, dtype=float))


TI = pose((0.1, -0.2, 0.3), (0.0, 0.0, 3.0))
TJ = pose((0.4, 0.1, -0.1), (1.0, 0.5, 0.2))
B_T_C = pose((0.0, 0.3, 0.1), (0.1, 0.05, -0.02))
MARKER = np.array([0.02, 0.0, 0.15])


def test_bearing_factor_zero_at_truth_and_jacobians_match_numeric():
    ki, kj = pose_key(0, 0), pose_key(1, 0)
    v = gtsam.Values()
    v.insert(ki, TI)
    v.insert(kj, TJ)
    exact = bearing_factor(ki, kj, predicted_bearing(TI, TJ, B_T_C, MARKER), 0.01, B_T_C, MARKER)
    assert exact.error(v) < 1e-20
    noisy = predicted_bearing(TI, TJ, B_T_C, MARKER) + np.array([0.01, -0.02, 0.0])
    f = bearing_factor(ki, kj, noisy, 0.01, B_T_C, MARKER)
    A = f.linearize(v).jacobian()[0] * 0.01  # unwhiten
    e0 = f.unwhitenedError(v)
    numeric = np.zeros((2, 12))
    for c, key in enumerate((ki, kj)):
        for d in range(6):
            step = np.zeros(6)
            step[d] = 1e-6
            v2 = gtsam.Values(v)
            v2.update(key, v.atPose3(key).retract(step))
            numeric[:, 6 * c + d] = (f.unwhitenedError(v2) - e0) / 1e-6
    np.testing.assert_allclose(A, numeric, atol=1e-4)


def test_mutual_bearings_with_known_baseline_recover_formation():
    """Seed 000 Sec. III-A / Problem 1: three robots see each other; one known distance fixes
    scale."""
    truth = [
        pose((0.0, 0, 0), (0.5, 0.5, 0.3)),
        pose((1.5, 0, 0), (0.5, 2.5, 0.4)),
        pose((-2.0, 0, 0), (2.5, 1.5, 0.2)),
    ]
    keys = [pose_key(r, 0) for r in range(3)]
    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.PriorFactorPose3(keys[0], truth[0], gtsam.noiseModel.Isotropic.Sigma(6, 1e-4)))
    for i in range(3):
        for j in range(3):
            if i != j:
                g.add(bearing_factor(keys[i], keys[j], predicted_bearing(truth[i], truth[j]), 1e-3))
    g.add(
        range_factor(
            keys[0], keys[1], np.linalg.norm(truth[0].translation() - truth[1].translation()), 1e-3
        )
    )
    init = gtsam.Values()
    rng = np.random.default_rng(0)
    for k, p in zip(keys, truth):
        init.insert(k, p.retract(0.1 * rng.standard_normal(6)))
    result = gtsam.LevenbergMarquardtOptimizer(g, init).optimize()
    for k, p in zip(keys, truth):
        np.testing.assert_allclose(result.atPose3(k).translation(), p.translation(), atol=1e-3)


def test_bearing_and_range_factors_reject_bad_input():
    with pytest.raises(ValueError, match="bearing"):
        bearing_factor(pose_key(0, 0), pose_key(1, 0), [np.nan, 0, 1], 0.01)
    with pytest.raises(ValueError, match="sigma"):
        bearing_factor(pose_key(0, 0), pose_key(1, 0), [0, 0, 1], 0.0)
    with pytest.raises(ValueError, match="differ"):
        bearing_factor(pose_key(0, 0), pose_key(0, 0), [0, 0, 1], 0.01)
    with pytest.raises(ValueError, match="marker"):
        bearing_factor(pose_key(0, 0), pose_key(1, 0), [0, 0, 1], 0.01, marker=[0, 1])
    with pytest.raises(ValueError, match="distance"):
        range_factor(pose_key(0, 0), pose_key(1, 0), -1.0, 0.01)


def test_range_factor_with_sensor_offset():
    ki, kj = pose_key(0, 0), pose_key(1, 0)
    v = gtsam.Values()
    v.insert(ki, TI)
    v.insert(kj, TJ)
    sensor = TI.compose(B_T_C).translation()
    d = float(np.linalg.norm(TJ.translation() - sensor))
    assert range_factor(ki, kj, d, 0.01, body_T_sensor=B_T_C).error(v) < 1e-16
    assert range_factor(ki, kj, d, 0.01).error(v) > 1.0  # without the offset the range is wrong


def candidate_set(poses, scores=None, cov=None):
    R = np.stack([p.rotation().matrix() for p in poses])
    t = np.stack([p.translation() for p in poses])
    return CandidateSet(
        R, t, np.ones(len(poses)) if scores is None else np.asarray(scores, float), covariance=cov
    )


def test_mixture_components_and_weights():
    genuine, pseudo = pose((0.1, 0, 0), (1.5, 1.5, 3.0)), pose((0.9, 0.2, 0), (1.0, 2.0, 2.5))
    cands = candidate_set([genuine, pseudo], scores=[3.0, 1.0])
    key = pose_key(0, 5)
    mix = candidate_mixture(cands, observation=5, observed_key=key)
    v = gtsam.Values()
    v.insert(key, genuine)
    errors = []
    for mode in range(2):
        dv = gtsam.DiscreteValues()
        dv[mode_key(5)] = mode
        errors.append(mix.error(v, dv))
    comps = component_factors(cands, key)
    nlc = comps[0].noiseModel().negLogConstant()
    # at the genuine pose, component 0 has zero Gaussian error: only -log w + normalizer remain
    assert errors[0] == pytest.approx(-np.log(0.75) + nlc)
    assert errors[1] > errors[0] + 10
    # between-factor form: observer key given
    between = component_factors(cands, key, observer_key=pose_key(1, 5))
    assert len(between) == 2 and all(isinstance(f, gtsam.BetweenFactorPose3) for f in between)


def test_mixture_rejects_bad_covariances_and_empty_sets():
    p = pose((0, 0, 0), (1, 1, 1))
    with pytest.raises(ValueError, match=r"\(1,6,6\)"):
        candidate_covariances(candidate_set([p], cov=np.eye(6)))
    bad = -np.eye(6)[None]
    with pytest.raises(ValueError, match="positive definite"):
        candidate_covariances(candidate_set([p], cov=bad))
    nan = np.full((1, 6, 6), np.nan)
    with pytest.raises(ValueError, match="NaN"):
        candidate_covariances(candidate_set([p], cov=nan))
    empty = CandidateSet(np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0))
    with pytest.raises(ValueError, match="no candidates"):
        candidate_mixture(empty, 0, pose_key(0, 0))


def test_surface_distance_is_free_along_the_plane():
    plane = SurfacePlane.sloped_ceiling()
    key = pose_key(3, 0)
    f = plane_distance_factor(key, plane, 0.01)
    on_plane = np.array([1.0, 2.0, 3.0])  # z = 2 + x
    along = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)
    for offset, expected in ((0.0, 0.0), (0.7, 0.0), (-1.3, 0.0)):
        v = gtsam.Values()
        v.insert(
            key,
            pose((0.3, 0.2, 0.1), on_plane + offset * along + 0.5 * offset * np.array([0, 1, 0])),
        )
        assert f.error(v) == pytest.approx(expected, abs=1e-12)
    v = gtsam.Values()
    v.insert(key, pose((0, 0, 0), on_plane + 0.02 * plane.normal))
    assert f.error(v) == pytest.approx(0.5 * (0.02 / 0.01) ** 2)


def test_surface_factors_pull_a_pose_onto_the_sloped_ceiling():
    plane = SurfacePlane.sloped_ceiling()
    key = pose_key(3, 0)
    g = gtsam.NonlinearFactorGraph()
    g.add(plane_distance_factor(key, plane, 0.005))
    g.add(plane_attitude_factor(key, plane, 0.02))
    start = pose((0.0, 0.0, 0.0), (1.0, 1.0, 2.5))
    g.add(gtsam.PriorFactorPose3(key, start, gtsam.noiseModel.Isotropic.Sigma(6, 10.0)))
    init = gtsam.Values()
    # body z initialized near the plane normal (AttitudeFactor's Unit3 error also vanishes at the
    # antipode)
    init.insert(
        key,
        gtsam.Pose3(
            gtsam.Rot3.AxisAngle(np.array([0.0, 1.0, 0.0]), np.pi * 0.7), start.translation()
        ),
    )
    r = gtsam.LevenbergMarquardtOptimizer(g, init).optimize().atPose3(key)
    assert abs(plane.distance(r.translation()[None])[0]) < 1e-4
    np.testing.assert_allclose(r.rotation().matrix()[:, 2], plane.normal, atol=1e-3)


def test_surface_rejects_bad_input():
    with pytest.raises(ValueError, match="non-zero"):
        SurfacePlane(np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="sigma"):
        plane_distance_factor(pose_key(0, 0), SurfacePlane.floor(), 0.0)
    with pytest.raises(ValueError, match="body_normal"):
        plane_attitude_factor(pose_key(0, 0), SurfacePlane.floor(), 0.1, body_normal=(0, 0, 0))
