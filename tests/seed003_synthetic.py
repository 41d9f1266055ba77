"""Shared synthetic seed-003 geometry for the EKF and factor-graph tests: a camera crawling
forward 1.2 cm/frame with small turns, KLT points on a wall at 2.6 m, the teammate's base centre
0.83 m ahead (seed 003 section III)."""

import numpy as np

from graphloc.cameras import PinholeCamera
from benchmarks.seed003_geometry import ideal_frames

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
    pts = np.column_stack(
        [rng.uniform(-0.9, 0.9, n_points), rng.uniform(-0.7, 0.1, n_points), np.full(n_points, 2.6)]
    )
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
    """Ideal measurement frames (0.5 px pixel noise) for `synthetic(...)`; returns frames, t, pts,
    base."""
    R, t, pts, base, cm, mm, odo, ostd = synthetic(n_points=n_points, seed=seed, **kw)
    return (
        ideal_frames(
            CAM,
            R,
            t,
            pts,
            base,
            cm,
            mm,
            odo,
            ostd,
            pixel_sigma=0.5,
            rng=np.random.default_rng(seed + 100),
        ),
        t,
        pts,
        base,
    )
