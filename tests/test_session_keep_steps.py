"""SessionConfig.keep_steps (issue 15, memory of long online runs): a session that keeps no
steps solves to the same estimates, holds no initial guesses online, and refuses `save`."""

import gtsam
import numpy as np
import pytest

from graphloc.pipelines.team_graph import GraphConfig
from graphloc.session import Session, SessionConfig

NOISE = gtsam.noiseModel.Isotropic.Sigma(6, 0.1)


def _chain(session: Session, n: int) -> None:
    for k in range(n):
        v = gtsam.Values()
        v.insert(k, gtsam.Pose3(gtsam.Rot3.Yaw(0.01 * k), [k + 0.1, 0.05 * k, 0]))
        factors = [gtsam.PriorFactorPose3(k, gtsam.Pose3(gtsam.Rot3(), [k, 0, 0]), NOISE)]
        if k:
            step = gtsam.Pose3(gtsam.Rot3(), [1, 0, 0])
            factors.append(gtsam.BetweenFactorPose3(k - 1, k, step, NOISE))
        session.add(factors, v, time=0.25 * k)


@pytest.mark.parametrize("lag", [0.0, 2.0])
def test_no_steps_kept_same_estimates_and_save_refused(tmp_path, lag):
    kept = Session(SessionConfig(mode="online", lag=lag))
    lean = Session(SessionConfig(mode="online", lag=lag, keep_steps=False))
    _chain(kept, 40)
    _chain(lean, 40)
    a, b = kept.estimate(), lean.estimate()
    assert a.size() == b.size() == 40
    assert all(a.atPose3(k).equals(b.atPose3(k), 0.0) for k in range(40))
    assert lean.initial is None and lean.live_variables() == kept.live_variables()
    assert len(lean.steps) == 40
    with pytest.raises(ValueError, match="keeps no steps"):
        lean.save(tmp_path / "s.json")
    assert not (tmp_path / "s.json").exists()
    kept.save(tmp_path / "k.json")  # the default still saves and replays exactly
    again = Session.load(tmp_path / "k.json").estimate()
    assert all(again.atPose3(k).equals(a.atPose3(k), 0.0) for k in range(40))
    # the checks that used the kept initial guesses still hold without them
    with pytest.raises(ValueError, match="already in the session"):
        v = gtsam.Values()
        v.insert(39, gtsam.Pose3())
        lean.add([], v, time=20.0)
    with pytest.raises(ValueError, match="without a value"):
        lean.add([gtsam.PriorFactorPose3(99, gtsam.Pose3(), NOISE)], gtsam.Values(), time=20.0)
    with pytest.raises(ValueError, match="no variable"):
        lean.estimate([99])
    if lag:
        assert lean.marginalized(0) and not lean.marginalized(39)
        with pytest.raises(ValueError, match="marginalized"):
            lean.add([gtsam.BetweenFactorPose3(0, 39, gtsam.Pose3(), NOISE)], gtsam.Values(), 20.0)


def test_batch_without_steps_solves_the_same_and_team_graph_sessions_keep_none():
    kept, lean = (Session(SessionConfig(mode="batch", keep_steps=k)) for k in (True, False))
    _chain(kept, 10)
    _chain(lean, 10)
    a, b = kept.estimate(), lean.estimate()
    assert np.allclose(
        [a.atPose3(k).translation() for k in range(10)],
        [b.atPose3(k).translation() for k in range(10)],
        atol=0,
    )
    for mode in ("batch", "online"):
        assert not GraphConfig().session_config(mode).keep_steps
