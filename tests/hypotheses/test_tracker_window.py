"""The HypothesisTracker's NumPy Pose3 maps and window update against GTSAM: Logmap,
LogmapDerivative, Expmap and adjointMap of every angle range, and the window update against
the GTSAM graph it replaces (PriorFactorPose3 + BetweenFactorPose3 + PriorFactorPose3 per
child, one GaussNewtonOptimizer, the inverse Hessian's blocks), iteration rule included."""

import gtsam
import numpy as np
import pytest

from graphloc.hypotheses import se3
from graphloc.hypotheses.window import window_updates
from graphloc.keys import pose_key


def _poses(rng, n, angle, spread=2.0):
    xi = rng.normal(size=(n, 6))
    xi[:, :3] *= angle / np.linalg.norm(xi[:, :3], axis=1, keepdims=True)
    xi[:, 3:] *= spread
    return [gtsam.Pose3.Expmap(x) for x in xi]


def _arrays(poses):
    return (
        np.array([p.rotation().matrix() for p in poses]),
        np.array([p.translation() for p in poses]),
    )


@pytest.mark.parametrize("angle", [1e-12, 1e-7, 1e-3, 0.3, 0.999, 1.001, 2.5, 3.14])
def test_pose3_maps_match_gtsam(angle):
    rng = np.random.default_rng(int(angle * 1e3))
    poses = _poses(rng, 50, angle)
    R, t = _arrays(poses)
    xi, jr_inv, ad = se3.log(R, t, jacobian=True)
    ref = np.array([gtsam.Pose3.Logmap(p) for p in poses])
    np.testing.assert_allclose(xi, ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        jr_inv, [gtsam.Pose3.LogmapDerivative(p) for p in poses], rtol=0, atol=1e-11
    )
    np.testing.assert_allclose(ad, [gtsam.Pose3.adjointMap(x) for x in ref], rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        se3.inverse_right_jacobian(ref),
        [gtsam.Pose3.LogmapDerivative(x) for x in ref],
        rtol=0,
        atol=1e-11,
    )
    T = se3.exp(ref)
    np.testing.assert_allclose(T[:, :3, :3], R, rtol=0, atol=1e-12)
    np.testing.assert_allclose(T[:, :3, 3], t, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(T[:, 3], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (len(T), 4)))


def _near_pi_rotation_matches_gtsam():
    R = gtsam.Rot3.Rodrigues(np.array([0.0, np.pi - 1e-9, 0.0])).matrix()[None]
    w, theta = se3.so3_log(R)
    return np.abs(w[0] - gtsam.Rot3.Logmap(gtsam.Rot3(R[0]))).max(), theta[0]


def test_rotation_log_near_pi_is_gtsams():
    err, theta = _near_pi_rotation_matches_gtsam()
    assert err == 0.0 and theta == pytest.approx(np.pi, abs=1e-8)


def gtsam_windows(parents, u, Q, candidates, iterations):
    """The window graph as GTSAM solves it (the tracker's implementation before the NumPy one):
    parents [(Pose3, cov)], candidates [(Pose3, cov)]."""
    odo_noise = gtsam.noiseModel.Gaussian.Covariance(Q)
    graph, init, order = gtsam.NonlinearFactorGraph(), gtsam.Values(), []
    for i, ((m, P), (z, C)) in enumerate(zip(parents, candidates)):
        k0, k1 = pose_key(0, 2 * i), pose_key(0, 2 * i + 1)
        graph.add(gtsam.PriorFactorPose3(k0, m, gtsam.noiseModel.Gaussian.Covariance(P)))
        graph.add(gtsam.BetweenFactorPose3(k0, k1, u, odo_noise))
        graph.add(gtsam.PriorFactorPose3(k1, z, gtsam.noiseModel.Gaussian.Covariance(C)))
        init.insert(k0, m)
        init.insert(k1, m.compose(u))
        order += [k0, k1]
    params = gtsam.GaussNewtonParams()
    params.setMaxIterations(iterations)
    optimizer = gtsam.GaussNewtonOptimizer(graph, init, params)
    result = optimizer.optimize()
    hessian = graph.linearize(result).hessian(gtsam.Ordering(order))[0]
    n = len(parents)
    blocks = hessian.reshape(n, 12, n, 12)[np.arange(n), :, np.arange(n), :]
    cov = np.linalg.inv(blocks)[:, 6:, 6:]
    poses = [result.atPose3(pose_key(0, 2 * i + 1)) for i in range(n)]
    return poses, 0.5 * (cov + np.swapaxes(cov, 1, 2)), optimizer.iterations()


def _spd(rng, n, scale):
    A = rng.normal(size=(n, 6, 6))
    return scale**2 * (A @ A.transpose(0, 2, 1) / 6 + 0.05 * np.eye(6))


@pytest.mark.parametrize("iterations", [0, 1, 2, 3, 6])
@pytest.mark.parametrize("spread", [1e-3, 0.05, 0.3])
def test_window_update_matches_the_gtsam_graph(iterations, spread):
    """Children far (0.3: several GN iterations) and near (1e-3: converged at once) their
    prediction; the result and the iteration count are GTSAM's."""
    rng = np.random.default_rng([iterations, int(spread * 1e3)])
    n = 4
    parents = [(m, P) for m, P in zip(_poses(rng, n, 0.8), _spd(rng, n, 0.05))]
    u = _poses(rng, 1, 0.05, 0.1)[0]
    Q = _spd(rng, 1, 0.01)[0]
    cands = [
        (m.compose(u).compose(gtsam.Pose3.Expmap(spread * rng.normal(size=6))), C)
        for (m, _), C in zip(parents, _spd(rng, n, 0.04))
    ]
    ref_poses, ref_cov, ref_iterations = gtsam_windows(parents, u, Q, cands, iterations)
    zR, zt = _arrays([z for z, _ in cands])
    pR, pt = _arrays([m.compose(u) for m, _ in parents])
    iR = pR.transpose(0, 2, 1) @ zR
    it = (pR.transpose(0, 2, 1) @ (zt - pt)[:, :, None])[:, :, 0]
    xi, jr, ad = se3.log(iR, it, jacobian=True)
    R, t, cov, done = window_updates(
        (np.array([P for _, P in parents]), Q, np.array([C for _, C in cands])),
        u.inverse().AdjointMap(),
        (zR, zt),
        (iR, it, xi, jr - ad),
        iterations,
    )
    assert done == ref_iterations
    refR, reft = _arrays(ref_poses)
    np.testing.assert_allclose(R, refR, rtol=0, atol=1e-10)
    np.testing.assert_allclose(t, reft, rtol=0, atol=1e-10)
    np.testing.assert_allclose(cov, ref_cov, rtol=1e-8, atol=1e-14)
