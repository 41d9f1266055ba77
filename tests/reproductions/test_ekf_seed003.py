"""Seed 003's EKF (eqs. 8-14): measurement model and Jacobian, initial settings, behaviour."""

import numpy as np
import pytest

from benchmarks.baselines.ekf_seed003 import (
    N_MOTION,
    TRACKER_ID,
    EkfConfig,
    Seed003Ekf,
    incremental_rotation,
    run_ekf,
)
from benchmarks.seed003_measures import axis_errors
from graphloc.seams import FrameInput
from graphloc.vision.features import FrameFeatures

from seed003_synthetic import CAM, frames_for, rot_y  # noqa: E402


def h_reference(ekf: Seed003Ekf, x: np.ndarray, which: np.ndarray) -> np.ndarray:
    """Eqs. 13-14 written out independently, with the incremental rotation of x[3:6] applied."""
    R = incremental_rotation(x[3:6]) @ ekf.R_global
    out = []
    for i in which:
        X = x[N_MOTION + 3 * i : N_MOTION + 3 * i + 3]
        a = R @ X
        Xc, Yc, Zcb = x[0] + a[0], x[1] + a[1], x[2] + x[6] * a[2]
        out += [Xc / (1 + Zcb), Yc / (1 + Zcb)]
    return np.array(out)


def test_jacobian_matches_finite_differences():
    frames, _, _, _ = frames_for(6)
    ekf = Seed003Ekf(CAM)
    for f in frames[:3]:
        ekf.step(f)
    ekf.R_global = rot_y(0.2) @ ekf.R_global  # a generic rotation
    which = np.arange(len(ekf.ids))
    h, H = ekf.predict_measurements(which)
    np.testing.assert_allclose(h, h_reference(ekf, ekf.x, which), rtol=1e-10, atol=1e-15)
    x0 = ekf.x.copy()
    num = np.zeros_like(H)
    for j in range(len(x0)):
        step = 1e-7 * max(1.0, abs(x0[j]))
        xp, xm = x0.copy(), x0.copy()
        xp[j] += step
        xm[j] -= step
        num[:, j] = (h_reference(ekf, xp, which) - h_reference(ekf, xm, which)) / (2 * step)
    np.testing.assert_allclose(H, num, rtol=1e-5, atol=1e-9 * np.abs(num).max())


def test_initial_state_follows_seed_section_iii():
    frames, _, _, _ = frames_for(5)
    ekf = Seed003Ekf(CAM, EkfConfig(tracker_setting="proper"))
    ekf.step(frames[0])
    assert ekf.ids[0] == TRACKER_ID and len(ekf.ids) == 6
    np.testing.assert_allclose(
        ekf.camera_pose()[1], 0.0, atol=1e-9
    )  # T = (0, 0, -1/beta): camera at the origin
    beta0 = 1.0 / (CAM.fx * EkfConfig().pixel_pitch)
    assert ekf.beta == pytest.approx(beta0, rel=0.05)
    ideal = Seed003Ekf(CAM, EkfConfig(tracker_setting="ideal"))
    ideal.step(frames[0])
    np.testing.assert_allclose(
        ideal.P[N_MOTION : N_MOTION + 3, N_MOTION : N_MOTION + 3], 0.0
    )  # ideal tracker
    noisy = Seed003Ekf(CAM, EkfConfig(tracker_setting="noisy"))
    noisy.step(frames[0])
    assert np.trace(noisy.P[N_MOTION : N_MOTION + 3, N_MOTION : N_MOTION + 3]) > np.trace(
        ekf.P[N_MOTION : N_MOTION + 3, N_MOTION : N_MOTION + 3]
    )


def test_more_features_improve_depth_translation():
    """Seed Fig. 6: with N = 1 (tracker point only) T_z is poorly estimated, many features fix
    it."""
    errs = {}
    for n in (1, 20):
        frames, truth, _, _ = frames_for(n - 1)
        errs[n] = axis_errors(run_ekf(frames, CAM), truth).mean(axis=0)
    assert errs[20][2] < 0.25 * errs[1][2]
    assert errs[20].max() < 0.01


def test_teammate_move_reinitializes_tracker_point():
    frames, truth, _, _ = frames_for(15, teammate_moves=True)
    ekf = Seed003Ekf(CAM)
    for f in frames:
        ekf.step(f)
    k = int(np.flatnonzero(ekf.ids == TRACKER_ID)[0])
    point = ekf.x[N_MOTION + 3 * k : N_MOTION + 3 * k + 3]
    assert np.linalg.norm(point - [0.03, 0.031, 0.87]) < 0.01  # moved 4 cm away
    assert axis_errors(np.array(ekf.positions), truth).max() < 0.02


def test_bad_input():
    frames, _, _, _ = frames_for(4)
    ekf = Seed003Ekf(CAM)
    no_mate = FrameInput(0.0, frames[0].features, None, False, False)
    with pytest.raises(ValueError, match="teammate"):
        ekf.step(no_mate)
    ekf.step(frames[1])
    with pytest.raises(ValueError, match="time"):
        ekf.step(frames[0])
    with pytest.raises(ValueError, match="pixels"):
        ekf.step(FrameInput(5.0, FrameFeatures(np.arange(3), np.zeros((2, 2))), None, True, False))
    with pytest.raises(ValueError, match="tracker_setting"):
        EkfConfig(tracker_setting="perfect")
    nan_frame = FrameInput(
        6.0,
        FrameFeatures(np.array([0, 1]), np.array([[np.nan, 1.0], [300.0, 200.0]])),
        frames[2].teammate,
        True,
        False,
    )
    ekf.step(nan_frame)
    assert ekf.skipped_pixels == 1


def test_points_behind_the_camera_are_counted_not_used():
    frames, _, _, _ = frames_for(5)
    ekf = Seed003Ekf(CAM)
    ekf.step(frames[0])
    ekf.x[N_MOTION + 3 * 1 + 2] = -1.0  # push the first KLT point behind the camera
    ekf.step(frames[1])
    assert ekf.skipped_behind == 1
    assert np.isfinite(ekf.x).all()
