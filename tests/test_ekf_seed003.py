"""Seed 003's EKF (eqs. 8-14): measurement model and Jacobian, initial settings, behaviour."""

import numpy as np
import pytest

from graphloc.baselines.ekf_seed003 import (N_MOTION, TRACKER_ID, EkfConfig, Seed003Ekf, incremental_rotation,
                                            run_ekf)
from graphloc.cameras import PinholeCamera
from graphloc.cooperative_sfm import FrameInput, axis_errors, ideal_frames
from graphloc.vision.features import FrameFeatures

CAM = PinholeCamera.from_fov(640, 480, np.radians(50))


def rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def synthetic(T=10, n_points=19, seed=0, teammate_moves=False):
    """Camera crawling forward 1.2 cm/frame with small turns; KLT points on a wall at 2.6 m;
    the teammate's base centre 0.83 m ahead (seed 003 section III)."""
    rng = np.random.default_rng(seed)
    yaw = np.cumsum(np.r_[0.0, rng.normal(0, 0.01, T - 1)])
    R = np.stack([rot_y(a) for a in yaw])
    t = np.zeros((T, 3))
    for k in range(1, T):
        t[k] = t[k - 1] + 0.012 * np.array([np.sin(yaw[k - 1]), 0.0, np.cos(yaw[k - 1])])
        t[k, 0] += rng.normal(0, 0.002)
    pts = np.column_stack([rng.uniform(-0.9, 0.9, n_points), rng.uniform(-0.7, 0.1, n_points), np.full(n_points, 2.6)])
    base = np.tile([0.03, 0.031, 0.83], (T, 1))
    cam_moved = np.r_[False, np.ones(T - 1, bool)]
    mate_moved = np.zeros(T, bool)
    odo = np.zeros(T)
    odo_std = np.zeros(T)
    if teammate_moves:  # the last two steps: camera stops, teammate crawls 2 cm away
        cam_moved[-2:] = False
        t[-2:] = t[-3]
        R[-2:] = R[-3]
        mate_moved[-2:] = True
        base[-2] = base[-3] + [0, 0, 0.02]
        base[-1] = base[-2] + [0, 0, 0.02]
        odo[-2:], odo_std[-2:] = 0.02, 0.0005
    return R, t, pts, base, cam_moved, mate_moved, odo, odo_std


def frames_for(n_points, seed=0, **kw):
    R, t, pts, base, cm, mm, odo, ostd = synthetic(n_points=n_points, seed=seed, **kw)
    return ideal_frames(CAM, R, t, pts, base, cm, mm, odo, ostd, pixel_sigma=0.5,
                        rng=np.random.default_rng(seed + 100)), t


def h_reference(ekf: Seed003Ekf, x: np.ndarray, which: np.ndarray) -> np.ndarray:
    """Eqs. 13-14 written out independently, with the incremental rotation of x[3:6] applied."""
    R = incremental_rotation(x[3:6]) @ ekf.R_global
    out = []
    for i in which:
        X = x[N_MOTION + 3 * i: N_MOTION + 3 * i + 3]
        a = R @ X
        Xc, Yc, Zcb = x[0] + a[0], x[1] + a[1], x[2] + x[6] * a[2]
        out += [Xc / (1 + Zcb), Yc / (1 + Zcb)]
    return np.array(out)


def test_jacobian_matches_finite_differences():
    frames, _ = frames_for(6)
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
    frames, _ = frames_for(5)
    ekf = Seed003Ekf(CAM, EkfConfig(tracker_setting="proper"))
    ekf.step(frames[0])
    assert ekf.ids[0] == TRACKER_ID and len(ekf.ids) == 6
    np.testing.assert_allclose(ekf.camera_pose()[1], 0.0, atol=1e-9)  # T = (0, 0, -1/beta): camera at the origin
    beta0 = 1.0 / (CAM.fx * EkfConfig().pixel_pitch)
    assert ekf.beta == pytest.approx(beta0, rel=0.05)
    ideal = Seed003Ekf(CAM, EkfConfig(tracker_setting="ideal"))
    ideal.step(frames[0])
    np.testing.assert_allclose(ideal.P[N_MOTION:N_MOTION + 3, N_MOTION:N_MOTION + 3], 0.0)  # ideal tracker
    noisy = Seed003Ekf(CAM, EkfConfig(tracker_setting="noisy"))
    noisy.step(frames[0])
    assert np.trace(noisy.P[N_MOTION:N_MOTION + 3, N_MOTION:N_MOTION + 3]) > np.trace(
        ekf.P[N_MOTION:N_MOTION + 3, N_MOTION:N_MOTION + 3])


def test_more_features_improve_depth_translation():
    """Seed Fig. 6: with N = 1 (tracker point only) T_z is poorly estimated, many features fix it."""
    errs = {}
    for n in (1, 20):
        frames, truth = frames_for(n - 1)
        errs[n] = axis_errors(run_ekf(frames, CAM), truth).mean(axis=0)
    assert errs[20][2] < 0.25 * errs[1][2]
    assert errs[20].max() < 0.01


def test_teammate_move_reinitializes_tracker_point():
    frames, truth = frames_for(15, teammate_moves=True)
    ekf = Seed003Ekf(CAM)
    for f in frames:
        ekf.step(f)
    k = int(np.flatnonzero(ekf.ids == TRACKER_ID)[0])
    point = ekf.x[N_MOTION + 3 * k: N_MOTION + 3 * k + 3]
    assert np.linalg.norm(point - [0.03, 0.031, 0.87]) < 0.01  # moved 4 cm away
    assert axis_errors(np.array(ekf.positions), truth).max() < 0.02


def test_bad_input():
    frames, _ = frames_for(4)
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
    nan_frame = FrameInput(6.0, FrameFeatures(np.array([0, 1]), np.array([[np.nan, 1.0], [300.0, 200.0]])),
                           frames[2].teammate, True, False)
    ekf.step(nan_frame)
    assert ekf.skipped_pixels == 1


def test_points_behind_the_camera_are_counted_not_used():
    frames, _ = frames_for(5)
    ekf = Seed003Ekf(CAM)
    ekf.step(frames[0])
    ekf.x[N_MOTION + 3 * 1 + 2] = -1.0  # push the first KLT point behind the camera
    ekf.step(frames[1])
    assert ekf.skipped_behind == 1
    assert np.isfinite(ekf.x).all()
