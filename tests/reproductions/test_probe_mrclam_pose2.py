"""scripts/probe_mrclam_pose2.py: the Pose2 form of each Pose3 factor the team graph builds for
a planar robot has the Pose3 factor's planar error at planar poses (the probe compares the two
estimators on the same problem), and a factor without a Pose2 form is refused."""

import importlib.util
import math
from pathlib import Path

import gtsam
import numpy as np
import pytest

from factors.range_bearing import known_landmark_factor_3d, robot_factor_3d

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "probe_mrclam_pose2.py"


@pytest.fixture(scope="module")
def probe():
    spec = importlib.util.spec_from_file_location("probe_mrclam_pose2", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def planar3(x, y, yaw):
    return gtsam.Pose3(gtsam.Rot3.Yaw(yaw), np.array([x, y, 0.0]))


A, B = gtsam.symbol("x", 1), gtsam.symbol("x", 2)
POSES = {A: (0.3, -1.2, 0.4), B: (1.1, 0.5, -2.0)}


def errors(f3, f2):
    v3, v2 = gtsam.Values(), gtsam.Values()
    for key in f3.keys():
        v3.insert(key, planar3(*POSES[key]))
        v2.insert(key, gtsam.Pose2(*POSES[key]))
    return np.asarray(f3.unwhitenedError(v3)), np.asarray(f2.unwhitenedError(v2))


def test_between_and_prior_keep_the_planar_error_and_marginal_noise(probe):
    cov = np.diag([0.01, 0.02, 0.03, 0.04, 0.05, 0.06]) ** 2
    noise = gtsam.noiseModel.Gaussian.Covariance(cov)
    between = gtsam.BetweenFactorPose3(A, B, planar3(0.7, 1.9, -2.1), noise)
    e3, e2 = errors(between, probe.to_pose2(between))
    np.testing.assert_allclose(e2, e3[[3, 4, 2]], atol=1e-9)
    np.testing.assert_allclose(
        probe.to_pose2(between).noiseModel().covariance(), cov[np.ix_([3, 4, 2], [3, 4, 2])]
    )
    prior = gtsam.PriorFactorPose3(A, planar3(0.2, -1.0, 0.5), noise)
    e3, e2 = errors(prior, probe.to_pose2(prior))
    np.testing.assert_allclose(e2, e3[[3, 4, 2]], atol=1e-9)


def test_known_landmark_recovers_landmark_and_measurement(probe):
    f3 = known_landmark_factor_3d(A, [2.0, 3.0, 0.0], 0.05, [0.6, 0.8, 0.0], 2.5)
    e3, e2 = errors(f3, probe.to_pose2(f3))
    np.testing.assert_allclose(e2, e3[:2], atol=1e-9)
    assert np.abs(e3).max() > 0.1  # an error the comparison can see


def test_bearing_range_between_robots_keeps_bearing_and_range(probe):
    bearing = 0.9
    f3 = robot_factor_3d(A, B, [math.cos(bearing), math.sin(bearing), 0.0], 1.7)
    f2 = probe.to_pose2(f3)
    assert isinstance(f2, gtsam.BearingRangeFactorPose2)
    x_a, x_b = gtsam.Pose2(*POSES[A]), gtsam.Pose2(*POSES[B])
    values = gtsam.Values()
    values.insert(A, x_a)
    values.insert(B, x_b)
    e2 = np.asarray(f2.unwhitenedError(values))
    seen = x_a.transformTo(x_b.translation())
    expected = [math.atan2(seen[1], seen[0]) - bearing, np.linalg.norm(seen) - 1.7]
    np.testing.assert_allclose(e2, expected, atol=1e-9)


def test_a_factor_without_a_planar_form_is_refused(probe):
    f = gtsam.PriorFactorPoint3(A, np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, 1.0))
    with pytest.raises(TypeError, match="PriorFactorPoint3"):
        probe.to_pose2(f)
