"""Session engine (batch LM / online iSAM2), odometry integration, robust kernels,
range-bearing factors -- on small synthetic planar problems with known truth."""

import gtsam
import numpy as np
import pytest

from graphloc.factors.odometry import (
    VelocityNoise,
    between_factor,
    relative_poses,
)
from benchmarks.planar_factors import integrate_unicycle
from graphloc.factors.range_bearing import landmark_factor_3d
from graphloc.factors.robust import GaussianChi2, Kernel, KernelPolicy, residuals, robust_noise
from graphloc.factors.bearing import (
    bearing_factor,
    bearing_to_point_factor,
    sensor_tie_factor,
)
from benchmarks.bearing_cost import predicted_bearing
from benchmarks.planar_factors import (
    bearing_range_2d,
    compose_poses,
    landmark_factor_2d,
    robot_factor_2d,
    to_body_frame_2d,
)
from graphloc.keys import landmark_key, pose_key, sensor_key
from graphloc.session import Session, SessionConfig

RNG_SEED = 7


def _problem(n_steps=30, n_outliers=3, seed=RNG_SEED):
    """Two robots driving circles near 4 known landmarks; returns per-step (factors, values, t)
    plus the true poses. A few landmark measurements are gross outliers."""
    rng = np.random.default_rng(seed)
    landmarks = np.array([[5.0, 0.0], [0.0, 5.0], [-5.0, 0.0], [0.0, -5.0]])
    t = np.arange(n_steps) * 0.5
    truth = {}
    for r, (radius, phase) in enumerate([(3.0, 0.0), (2.0, 1.5)]):
        ang = phase + 0.2 * t
        truth[r] = np.stack([radius * np.cos(ang), radius * np.sin(ang), ang + np.pi / 2], axis=1)
    odo_sig = np.array([0.02, 0.02, 0.01])
    rb_sig = (0.02, 0.05)
    kern = KernelPolicy({"landmark": Kernel("cauchy", 2.0), "inter_robot": Kernel("huber", 1.345)})
    outlier_steps = set(rng.choice(np.arange(2, n_steps), n_outliers, replace=False).tolist())
    steps, dr = [], {r: truth[r][0].copy() for r in truth}
    for k in range(n_steps):
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        for r, poses in truth.items():
            key = pose_key(r, k)
            if k == 0:
                graph.add(
                    gtsam.PriorFactorPose2(
                        key, gtsam.Pose2(*poses[0]), gtsam.noiseModel.Isotropic.Sigma(3, 0.01)
                    )
                )
                values.insert(key, gtsam.Pose2(*poses[0]))
            else:
                delta = relative_poses(poses[k - 1 : k + 1])[0] + rng.normal(0, odo_sig)
                graph.add(
                    between_factor(
                        pose_key(r, k - 1), key, gtsam.Pose2(*delta), np.diag(odo_sig**2)
                    )
                )
                dr[r] = compose_poses(dr[r][None], delta[None])[0]
                values.insert(key, gtsam.Pose2(*dr[r]))
            b, rng_ = bearing_range_2d(np.repeat(poses[k : k + 1], 4, 0), landmarks)
            for j in range(4):
                meas_r = rng_[j] + rng.normal(0, rb_sig[1])
                if j == 0 and r == 0 and k in outlier_steps:
                    meas_r += 4.0  # gross outlier (misread)
                graph.add(
                    landmark_factor_2d(
                        key,
                        landmark_key(j),
                        b[j] + rng.normal(0, rb_sig[0]),
                        meas_r,
                        rb_sig,
                        kern.kernel("landmark"),
                    )
                )
        b, rr = bearing_range_2d(truth[0][k : k + 1], truth[1][k : k + 1, :2])
        graph.add(
            robot_factor_2d(
                pose_key(0, k), pose_key(1, k), b[0], rr[0], rb_sig, kern.kernel("inter_robot")
            )
        )
        if k == 0:
            for j, xy in enumerate(landmarks):
                graph.add(
                    gtsam.PriorFactorPoint2(
                        landmark_key(j), xy, gtsam.noiseModel.Isotropic.Sigma(2, 1e-3)
                    )
                )
                values.insert(landmark_key(j), xy + 0.1)
        steps.append((graph, values, float(t[k])))
    return steps, truth, len(outlier_steps)


def _errors(values, truth):
    return np.array(
        [
            np.hypot(*(values.atPose2(pose_key(r, k)).translation() - truth[r][k, :2]))
            for r in truth
            for k in range(len(truth[r]))
        ]
    )


def _run(mode, steps, **cfg):
    s = Session(SessionConfig(mode=mode, **cfg))
    for g, v, t in steps:
        s.add(g, v, time=t)
    return s


@pytest.mark.parametrize("optimizer", ["gauss_newton", "dogleg"])
def test_batch_and_online_agree_and_beat_odometry(optimizer):
    steps, truth, n_out = _problem()
    batch = _run("batch", steps)
    online = _run("online", steps, isam2_optimizer=optimizer)
    eb, eo = _errors(batch.estimate(), truth), _errors(online.estimate(), truth)
    assert np.sqrt(np.mean(eb**2)) < 0.05
    assert np.sqrt(np.mean(eo**2)) < 1.2 * np.sqrt(np.mean(eb**2)) + 0.01
    assert batch.batch_iterations >= 1
    assert len(online.latencies()) == len(steps) and np.all(online.latencies() > 0)
    # the outliers are the factors the kernel down-weights
    report = residuals(batch.graph, batch.estimate())
    assert report.robust.sum() == sum(2 * 4 + 1 for _ in steps)
    assert report.downweighted(0.1).sum() == n_out
    # the chi-square without kernels in one C++ pass equals the factor-by-factor one
    chi2 = GaussianChi2()
    for g, _, _ in steps:
        chi2.add(g)
    assert chi2(batch.estimate()) == pytest.approx(report.chi2.sum(), rel=1e-9)
    assert chi2.dim == report.dims.sum()
    assert chi2(batch.estimate()) > 2 * batch.error()  # the outliers' kernels muted them


def test_gaussian_chi2_judges_custom_factors_and_uninformative_ranges():

    huber = Kernel("huber", 1.0)
    a, b = pose_key(0, 0), pose_key(1, 0)
    values = gtsam.Values()
    values.insert(a, gtsam.Pose3())
    values.insert(b, gtsam.Pose3(gtsam.Rot3.Yaw(0.3), gtsam.Point3(2.0, 1.0, 0.5)))
    factors = [
        gtsam.PriorFactorPose3(a, gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 0.1)),
        gtsam.BetweenFactorPose3(
            a, b, gtsam.Pose3(), robust_noise(gtsam.noiseModel.Isotropic.Sigma(6, 0.1), huber)
        ),
        # a Python CustomFactor (a camera off the body origin) and a rotation-only bearing
        bearing_factor(
            a,
            b,
            np.array([1.0, 0.0, 0.0]),
            0.02,
            gtsam.Pose3(gtsam.Rot3(), gtsam.Point3(0.1, 0.0, 0.2)),
            kernel=huber,
        ),
        bearing_factor(a, b, np.array([0.0, 1.0, 0.0]), 0.02, kernel=huber),
    ]
    chi2 = GaussianChi2()
    chi2.add(factors)
    graph = gtsam.NonlinearFactorGraph()
    for f in factors:
        graph.push_back(f)
    report = residuals(graph, values)
    assert chi2(values) == pytest.approx(report.chi2.sum(), rel=1e-9)
    assert chi2.dim == report.dims.sum() == 6 + 6 + 2 + 2
    assert chi2.loose.size() == 1


def test_marginal_covariance_batch_online():
    steps, _, _ = _problem(n_steps=10)
    key = pose_key(0, 9)
    cb = _run("batch", steps).marginal_covariance(key)
    co = _run("online", steps, relinearize_skip=1, extra_updates=2).marginal_covariance(key)
    assert cb.shape == (3, 3) and np.all(np.linalg.eigvalsh(cb) > 0)
    np.testing.assert_allclose(co, cb, rtol=0.05, atol=1e-7)


def test_session_rejects_bad_input():
    s = Session(SessionConfig(mode="online"))
    g = gtsam.NonlinearFactorGraph()
    g.add(
        gtsam.PriorFactorPose2(
            pose_key(0, 0), gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 1)
        )
    )
    v = gtsam.Values()
    v.insert(pose_key(0, 0), gtsam.Pose2())
    s.add(g, v, time=1.0)
    g2 = gtsam.NonlinearFactorGraph()
    g2.add(
        gtsam.BetweenFactorPose2(
            pose_key(0, 0), pose_key(0, 1), gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 1)
        )
    )
    with pytest.raises(ValueError, match="without a value"):
        s.add(g2, gtsam.Values(), time=2.0)
    v2 = gtsam.Values()
    v2.insert(pose_key(0, 1), gtsam.Pose2())
    with pytest.raises(ValueError, match="backwards"):
        s.add(g2, v2, time=0.5)
    with pytest.raises(ValueError, match="not finite"):
        s.add(g2, v2, time=float("nan"))
    with pytest.raises(ValueError, match="already"):
        s.add(gtsam.NonlinearFactorGraph(), v, time=3.0)
    with pytest.raises(ValueError, match="mode"):
        SessionConfig(mode="fast")
    with pytest.raises(ValueError, match="isam2_optimizer"):
        SessionConfig(isam2_optimizer="newton")


def test_integrate_unicycle_exact_circle_and_covariance():
    # constant v, w: exact circle of radius v/w whatever the sampling
    t = np.linspace(0, 10, 137)
    v, w = np.full_like(t, 0.5), np.full_like(t, 0.25)
    kf = np.linspace(0, 10, 21)
    out = integrate_unicycle(t, v, w, kf, VelocityNoise())
    ang = 0.25 * kf
    np.testing.assert_allclose(out.poses[:, 0], 2.0 * np.sin(ang), atol=1e-12)
    np.testing.assert_allclose(out.poses[:, 1], 2.0 * (1 - np.cos(ang)), atol=1e-12)
    np.testing.assert_allclose(out.deltas, relative_poses(out.poses), atol=1e-12)
    assert out.covariances.shape == (20, 3, 3)
    assert np.all(np.linalg.eigvalsh(out.covariances) > 0)
    # covariance matches Monte Carlo of the same white velocity noise (one keyframe step)
    rng = np.random.default_rng(0)
    noise = VelocityNoise(density_v=0.1, density_w=0.2, floor_xy=1e-6, floor_theta=1e-6)
    ts = np.linspace(0, 1, 201)
    dt = 1 / 200
    samples = []
    for _ in range(1500):
        vv = 0.5 + rng.normal(0, noise.density_v / np.sqrt(dt), ts.size)
        ww = 0.3 + rng.normal(0, noise.density_w / np.sqrt(dt), ts.size)
        samples.append(integrate_unicycle(ts, vv, ww, np.array([0.0, 1.0]), noise).deltas[0])
    nominal = integrate_unicycle(
        ts, np.full(ts.size, 0.5), np.full(ts.size, 0.3), np.array([0.0, 1.0]), noise
    )
    d = np.array(samples) - nominal.deltas[0]
    # express the spread in the end frame's tangent (rotate by the relative heading)
    c, s = np.cos(nominal.deltas[0, 2]), np.sin(nominal.deltas[0, 2])
    body = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], 1)
    mc, model = np.cov(body.T), nominal.covariances[0]
    scale = np.sqrt(
        np.outer(np.diag(model), np.diag(model))
    )  # sampling std of a covariance entry ~ scale/sqrt(N)
    assert np.all(np.abs(mc - model) < 4 * scale / np.sqrt(len(samples)) + 1e-6)


def test_integrate_unicycle_rejects_bad_input():
    with pytest.raises(ValueError, match="NaN"):
        integrate_unicycle(
            np.array([0.0, 1.0]), np.array([0.1, np.nan]), np.zeros(2), np.array([0.0, 1.0])
        )
    with pytest.raises(ValueError, match="non-decreasing"):
        integrate_unicycle(np.array([1.0, 0.0]), np.zeros(2), np.zeros(2), np.array([0.0, 1.0]))


def test_between_factor_pose3_matrix_and_bad_covariance():
    T = np.eye(4)
    T[:3, 3] = [1, 2, 3]
    f = between_factor(1, 2, T, np.eye(6) * 0.01)
    assert isinstance(f, gtsam.BetweenFactorPose3)
    with pytest.raises(ValueError, match="positive definite"):
        between_factor(1, 2, gtsam.Pose2(), -np.eye(3))
    with pytest.raises(ValueError, match="3x3"):
        between_factor(1, 2, gtsam.Pose2(), np.eye(6))


def test_robust_kernels_by_name():
    base = gtsam.noiseModel.Diagonal.Sigmas([0.1, 0.1])
    for name in ("huber", "cauchy", "tukey", "gemanmcclure", "dcs", "Geman-McClure"):
        m = robust_noise(base, Kernel(name, 1.0))
        assert isinstance(m, gtsam.noiseModel.Robust)
        assert m.robust().weight(0.1) > m.robust().weight(10.0)
    assert robust_noise(base, Kernel("none")) is base
    assert Kernel.parse("cauchy:2.5") == Kernel("cauchy", 2.5)
    with pytest.raises(ValueError, match="unknown robust kernel"):
        Kernel("bisquare-ish")


def test_range_bearing_3d_and_body_frame():
    f = landmark_factor_3d(pose_key(0, 0), landmark_key(1), [1.0, 0.0, 0.0], 2.0)
    v = gtsam.Values()
    v.insert(pose_key(0, 0), gtsam.Pose3())
    v.insert(landmark_key(1), np.array([2.0, 0.0, 0.0]))
    assert f.error(v) < 1e-12
    with pytest.raises(ValueError):
        landmark_factor_2d(1, 2, 0.1, -1.0)
    with pytest.raises(ValueError):
        robot_factor_2d(1, 2, np.nan, 1.0)
    # sensor 0.1 m ahead, yawed 90 deg: a point 1 m along sensor x is at (0.1, 1) in the body
    b, r = to_body_frame_2d(np.array([0.0]), np.array([1.0]), (0.1, 0.0, np.pi / 2))
    np.testing.assert_allclose([b[0], r[0]], [np.arctan2(1, 0.1), np.hypot(1, 0.1)])


def test_underconstrained_online_update_is_a_value_error():
    s = Session(SessionConfig(mode="online"))
    g = gtsam.NonlinearFactorGraph()
    g.add(robot_factor_2d(pose_key(0, 0), pose_key(1, 0), 0.1, 1.0))  # no prior: gauge freedom
    v = gtsam.Values()
    v.insert(pose_key(0, 0), gtsam.Pose2())
    v.insert(pose_key(1, 0), gtsam.Pose2(1, 0, 0))
    with pytest.raises(ValueError, match="iSAM2 update failed"):
        s.add(g, v, time=0.0)


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_unknown_keys_are_clear_errors(mode):
    session = Session(SessionConfig(mode=mode))
    values = gtsam.Values()
    values.insert(pose_key(0, 0), gtsam.Pose2())
    session.add(
        [
            gtsam.PriorFactorPose2(
                pose_key(0, 0), gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 0.1)
            )
        ],
        values,
        time=1.0,
    )
    with pytest.raises(ValueError, match="no variable"):
        session.estimate([pose_key(0, 1)])
    with pytest.raises(ValueError, match="no variable"):
        session.marginal_covariance(pose_key(0, 1))
    assert session.marginal_covariance(pose_key(0, 0)).shape == (3, 3)
    values = gtsam.Values()
    values.insert(pose_key(0, 1), gtsam.Pose2())
    session.add(
        [
            gtsam.BetweenFactorPose2(
                pose_key(0, 0),
                pose_key(0, 1),
                gtsam.Pose2(),
                gtsam.noiseModel.Isotropic.Sigma(3, 0.1),
            )
        ],
        values,
    )  # time None: same as before
    assert session.steps[-1].time == 1.0


I0 = "step 0, item 0: "


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_offset_bearings_through_a_sensor_pose_match_the_custom_factor(mode):
    """An offset camera's bearings (to a teammate and to a landmark) as GTSAM built-ins on a
    sensor pose tied to the body pose (`sensor_tie_factor`) give the estimate of the Python
    CustomFactor route on the same graph; the sensor key passes iSAM2's per-symbol thresholds."""
    rng = np.random.default_rng(3)
    E = gtsam.Pose3(gtsam.Rot3.Ypr(0.3, -0.1, 0.2), gtsam.Point3(0.25, -0.1, 0.4))
    n = 6
    body = [
        gtsam.Pose3(gtsam.Rot3.Yaw(0.2 * k), gtsam.Point3(0.3 * k, 0.1 * k, 0.0)) for k in range(n)
    ]
    other = gtsam.Pose3(gtsam.Rot3.Yaw(-0.4), gtsam.Point3(3.0, 2.0, 0.5))
    point = np.array([2.0, -3.0, 1.0])
    o, lk = pose_key(1, 0), landmark_key(0)
    rel = gtsam.noiseModel.Isotropic.Sigma(6, 0.05)

    def noisy(b):
        b = b + rng.normal(0, 0.01, 3)
        return b / np.linalg.norm(b)

    meas = [
        (noisy(predicted_bearing(T, other, E)), noisy(E.transformTo(T.transformTo(point))))
        for T in body
    ]

    def steps(sensor_route: bool) -> list:
        out = []
        for k in range(n):
            x = pose_key(0, k)
            g, v = [], gtsam.Values()
            v.insert(x, body[k].compose(gtsam.Pose3.Expmap(rng_start[k])))
            if k == 0:
                g += [
                    gtsam.PriorFactorPose3(x, body[0], gtsam.noiseModel.Isotropic.Sigma(6, 0.01)),
                    gtsam.PriorFactorPose3(o, other, gtsam.noiseModel.Isotropic.Sigma(6, 0.02)),
                    gtsam.PriorFactorPoint3(lk, point, gtsam.noiseModel.Isotropic.Sigma(3, 0.05)),
                ]
                v.insert(o, other)
                v.insert(lk, point + 0.05)
            else:
                g.append(
                    gtsam.BetweenFactorPose3(
                        pose_key(0, k - 1), x, body[k - 1].between(body[k]), rel
                    )
                )
            if sensor_route:
                s = sensor_key(0, 0, k)
                g.append(sensor_tie_factor(x, s, E))
                v.insert(s, v.atPose3(x).compose(E))
                g.append(bearing_factor(s, o, meas[k][0], 0.01))
                g.append(bearing_to_point_factor(s, lk, meas[k][1], 0.01))
            else:
                g.append(bearing_factor(x, o, meas[k][0], 0.01, E))
                g.append(bearing_to_point_factor(x, lk, meas[k][1], 0.01, E))
            out.append((g, v, float(k)))
        return out

    rng_start = rng.normal(0, 0.02, (n, 6))
    cfg = {"relinearize_translation": 0.01} if mode == "online" else {}
    if mode == "online":
        cfg["extra_updates"] = 5
    custom = _run(mode, steps(False), **cfg).estimate()
    routed = _run(mode, steps(True), **cfg).estimate()
    for key in [pose_key(0, k) for k in range(n)] + [o]:
        a, b = custom.atPose3(key), routed.atPose3(key)
        assert np.linalg.norm(gtsam.Pose3.Logmap(a.between(b))) < 5e-6, key
    assert np.linalg.norm(custom.atPoint3(lk) - routed.atPoint3(lk)) < 5e-6
