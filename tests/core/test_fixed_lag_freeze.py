"""A variable leaving the fixed lag keeps the estimate of a full back-substitution (issue 15):
iSAM2's own back-substitution stops where the solution changes less than the wildfire
threshold, and an estimate frozen from it would stay stale for good."""

import gtsam
import numpy as np

from graphloc.session import Session, SessionConfig

NOISE = gtsam.noiseModel.Isotropic.Sigma(6, 0.1)
LOOSE = gtsam.noiseModel.Isotropic.Sigma(6, 10.0)


def _run(wildfire: float):
    """A chain whose first pose is pulled by a prior arriving late (still inside the lag):
    returns (frozen estimate of pose 0, iSAM2's own estimate of it right before it left)."""
    s = Session(
        SessionConfig(
            mode="online",
            lag=2.0,
            marginalize_every=2.0,  # few stamps: few recent keys always re-eliminated
            wildfire_threshold=wildfire,
            relinearize_threshold=1e3,  # one linearization: the estimates are linear solves
        )
    )
    own = None
    for k in range(20):
        v = gtsam.Values()
        v.insert(k, gtsam.Pose3(gtsam.Rot3(), [float(k), 0, 0]))
        factors = [gtsam.PriorFactorPose3(k, gtsam.Pose3(gtsam.Rot3(), [k, 0, 0]), LOOSE)]
        if k:
            step = gtsam.Pose3(gtsam.Rot3(), [1, 0, 0])
            factors.append(gtsam.BetweenFactorPose3(k - 1, k, step, NOISE))
        if k == 10:  # pose 9 known well: the whole chain behind it shifts by ~0.3 m in y
            pose = gtsam.Pose3(gtsam.Rot3(), [9, 0.3, 0])
            factors.append(gtsam.PriorFactorPose3(9, pose, NOISE))
        if not s.marginalized(0):
            own = s._isam.calculateEstimatePose3(0) if k else None
        s.add(factors, v, time=0.25 * k)
    assert s.marginalized(0)
    return s.estimate([0]).atPose3(0), own


def test_frozen_estimate_is_the_full_back_substitution():
    exact, _ = _run(wildfire=0.0)  # back-substitution never stops early
    frozen, own = _run(wildfire=1.0)  # iSAM2's own stops at once
    assert abs(exact.y() - 0.3) < 0.05  # the late prior moved pose 0
    assert np.allclose(frozen.translation(), exact.translation(), atol=1e-9)
    assert np.allclose(frozen.rotation().matrix(), exact.rotation().matrix(), atol=1e-9)
    assert abs(own.y() - exact.y()) > 0.1  # what freezing iSAM2's own estimate would keep
