"""Max-mixture factor (Olson & Agarwal, RSS 2012) in factors/mixture.py."""

import gtsam
import numpy as np
import pytest

from graphloc.candidates import CandidateSet
from graphloc.factors.mixture import component_factors, max_mixture_factor
from benchmarks.candidate_mixtures import candidate_max_mixture, candidate_mixture
from graphloc.keys import mode_key, pose_key
from graphloc.session import Session, SessionConfig

A, B = pose_key(0, 0), pose_key(1, 0)


def two_candidates(scores=(1.0, 1.0)):
    """Relative pose A -> B: the genuine one (index 0) and a mirror 0.3 rad / 5 cm away."""
    R = np.stack([gtsam.Rot3.Ry(0.2).matrix(), gtsam.Rot3.Ry(-0.1).matrix()])
    t = np.array([[0.1, 0.0, 0.8], [0.15, 0.0, 0.8]])
    return CandidateSet(R, t, np.array(scores, float))


def values_at(pose_b: gtsam.Pose3) -> gtsam.Values:
    v = gtsam.Values()
    v.insert(A, gtsam.Pose3())
    v.insert(B, pose_b)
    return v


def test_error_is_the_min_over_components_up_to_a_constant():
    cands = two_candidates((0.3, 0.7))
    mix = candidate_max_mixture(cands, B, A)
    comps = component_factors(cands, B, A)
    w = cands.weights()
    for pose in (
        cands.poses()[0],
        cands.poses()[1],
        gtsam.Pose3(gtsam.Rot3.Ry(0.05), [0.12, 0.01, 0.79]),
    ):
        v = values_at(pose)
        terms = np.array(
            [
                -np.log(w[k]) + f.noiseModel().negLogConstant() + f.error(v)
                for k, f in enumerate(comps)
            ]
        )
        np.testing.assert_allclose(mix.component_errors(v), terms)
        assert mix.active(v) == int(np.argmin(terms))
        assert mix.factor.error(v) == pytest.approx(
            terms.min() - mix.constants.min(), rel=1e-9, abs=1e-9
        )


def test_jacobians_match_numerical_differentiation():
    cands = two_candidates()
    mix = candidate_max_mixture(cands, B, A)
    base = values_at(gtsam.Pose3(gtsam.Rot3.RzRyRx(0.02, 0.15, -0.03), [0.11, 0.02, 0.78]))
    base.update(A, gtsam.Pose3(gtsam.Rot3.Rx(0.05), [0.01, -0.02, 0.0]))
    A_lin, b = mix.factor.linearize(base).jacobian()
    np.testing.assert_allclose(-b, mix.factor.whitenedError(base), atol=1e-12)
    eps = 1e-6
    numeric = np.zeros_like(A_lin)
    col = 0
    for key in (A, B):  # CustomFactor keys are sorted: A < B
        for i in range(6):
            cols = []
            for sign in (1.0, -1.0):
                d = np.zeros(6)
                d[i] = sign * eps
                delta = gtsam.VectorValues()
                for other in (A, B):
                    delta.insert(other, d if other == key else np.zeros(6))
                cols.append(mix.factor.whitenedError(base.retract(delta)))
            numeric[:, col] = (cols[0] - cols[1]) / (2 * eps)
            col += 1
    np.testing.assert_allclose(A_lin, numeric, atol=1e-6)


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_picks_the_component_consistent_with_other_evidence(mode):
    """Equal weights, the start at the wrong candidate; a second, independent observation of
    B supports candidate 0 -> the optimum lands on candidate 0 and it is the active one."""
    cands = two_candidates()
    mix = candidate_max_mixture(cands, B, A)
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose3(A, gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 1e-4)))
    graph.add(mix.factor)
    graph.add(
        gtsam.PriorFactorPose3(
            B, cands.poses()[0], gtsam.noiseModel.Diagonal.Sigmas(np.array([0.01] * 3 + [0.01] * 3))
        )
    )
    init = values_at(cands.poses()[1])
    session = Session(SessionConfig(mode=mode, relinearize_threshold=0.001, extra_updates=5))
    session.add(graph, init, time=0.0)
    est = session.estimate()
    assert mix.active(init) == 1 and mix.active(est) == 0
    assert est.atPose3(B).equals(cands.poses()[0], 1e-3)


def test_component_groups_add_their_errors():
    n3 = gtsam.noiseModel.Isotropic.Sigma(3, 0.1)
    groups = [
        [
            gtsam.PriorFactorPoint3(1, gtsam.Point3(0, 0, 0), n3),
            gtsam.PriorFactorPoint3(1, gtsam.Point3(0, 0, 1), n3),
        ],
        [gtsam.PriorFactorPoint3(1, gtsam.Point3(5, 0, 0), n3)],
    ]
    mix = max_mixture_factor(groups, [1.0, 1.0])
    assert mix.residual_dim == 7
    v = gtsam.Values()
    v.insert(1, gtsam.Point3(0, 0, 0.5))
    assert mix.active(v) == 0
    np.testing.assert_allclose(
        mix.component_errors(v)[0] - mix.constants[0], sum(f.error(v) for f in groups[0])
    )
    graph = gtsam.NonlinearFactorGraph()
    graph.add(mix.factor)
    est = gtsam.LevenbergMarquardtOptimizer(graph, v).optimize()
    np.testing.assert_allclose(est.atPoint3(1), [0, 0, 0.5], atol=1e-9)


def test_bad_inputs_raise_value_error():
    cands = two_candidates()
    comps = component_factors(cands, B, A)
    with pytest.raises(ValueError, match="no components"):
        max_mixture_factor([], [])
    with pytest.raises(ValueError, match="has no factors"):
        max_mixture_factor([comps[0], []], [1.0, 1.0])
    with pytest.raises(ValueError, match="weight\\[1\\]"):
        max_mixture_factor(comps, [1.0, np.nan])
    with pytest.raises(ValueError, match="weight\\[0\\]"):
        max_mixture_factor(comps, [0.0, 1.0])
    with pytest.raises(ValueError, match="shape"):
        max_mixture_factor(comps, [1.0])
    with pytest.raises(ValueError, match="different variables"):
        max_mixture_factor(
            [comps[0], gtsam.PriorFactorPose3(B, gtsam.Pose3(), gtsam.noiseModel.Unit.Create(6))],
            [1.0, 1.0],
        )
    robust = gtsam.noiseModel.Robust.Create(
        gtsam.noiseModel.mEstimator.Huber.Create(1.0), gtsam.noiseModel.Unit.Create(6)
    )
    with pytest.raises(ValueError, match="robust"):
        max_mixture_factor(
            [comps[0], gtsam.BetweenFactorPose3(A, B, gtsam.Pose3(), robust)], [1.0, 1.0]
        )
    with pytest.raises(ValueError, match="NoiseModelFactor"):
        max_mixture_factor([comps[0], "factor"], [1.0, 1.0])
    with pytest.raises(ValueError, match="empty"):
        candidate_max_mixture(
            CandidateSet(np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0)), B, A
        )
    with pytest.raises(ValueError, match="NaN"):
        CandidateSet(np.stack([np.eye(3)] * 2), [[0, 0, np.nan], [0, 0, 1]], np.ones(2))
    bad_cov = np.broadcast_to(np.eye(6), (2, 6, 6)).copy()
    bad_cov[1, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        candidate_max_mixture(
            CandidateSet(cands.R, cands.t, cands.scores, covariance=bad_cov), B, A
        )


def test_candidate_with_underflowed_score_keeps_its_component():
    """A score of exactly 0 (exp(-r^2/2s^2) underflow) must not make the mixture builders raise;
    the candidate keeps its index and is never chosen over a fitting one."""
    cands = two_candidates()
    zero = CandidateSet(cands.R, cands.t, np.array([1.0, 0.0]))
    mix = candidate_max_mixture(zero, B, A)
    assert len(mix.components) == 2
    hybrid = candidate_mixture(zero, 0, B, A)
    assert hybrid.discreteKeys().at(0) == (mode_key(0), 2)
    for pose in zero.poses():  # even at its own pose the zero-score candidate is not chosen
        modes = [gtsam.DiscreteValues() for _ in range(2)]
        for m, dv in enumerate(modes):
            dv[mode_key(0)] = m
        errors = [hybrid.error(values_at(pose), dv) for dv in modes]
        assert np.isfinite(errors).all() and errors[0] < errors[1], errors
