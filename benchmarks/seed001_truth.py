"""The ground truth's errors for benchmarks.seed001_readings (issue 20, seed 001
experiment 1, 001_0f8f8dae37ce6b79.txt Sec. V-A): Vicon's reading of each frame (a lag along the
trajectory, a hand-eye rotation about an axis at a given angle to the optical axis, a target
offset, per-frame jitter), the seed's errors against it and the paper's six scored numbers.
Every reading sees the same DIRECTIONS axes and standard-normal jitter of one seed (common
random numbers)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks.seed001_report import PAPER

DIRECTIONS = 16  # axes per offset magnitude (common to all readings), statistics averaged
AT_3M = 2.8  # run 2 frames at >= this distance count as "at 3 m" (as seed001.summarize)
SCORED = (
    ("run1", "pos_mean_cm"),
    ("run1", "pos_std_cm"),
    ("run1", "rot_mean_deg"),
    ("run1", "rot_std_deg"),
    ("run2_at_3m", "pos_mean_cm"),
    ("run2_at_3m", "rot_mean_deg"),
)


def _axes(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def tilted_axes(rng: np.random.Generator, n: int, tilt_deg: float) -> np.ndarray:
    """(n, 3) unit axes in the camera frame at `tilt_deg` from the optical axis (z): random
    azimuths, alternating signs along z."""
    az = rng.uniform(0.0, 2.0 * np.pi, n)
    th = np.radians(tilt_deg)
    sign = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    return np.column_stack([np.sin(th) * np.cos(az), np.sin(th) * np.sin(az), sign * np.cos(th)])


def lag_steps(frames: list) -> np.ndarray:
    """(n, 3) rotation vector [rad] from frame k to k + 1 in frame k's camera frame (the last
    frame: zero)."""
    R = np.array([f["R"] for f in frames])
    nxt = np.minimum(np.arange(len(R)) + 1, len(R) - 1)
    return Rotation.from_matrix(np.einsum("kji,kjl->kil", R, R[nxt])).as_rotvec()


def truth(frames: list, lag: float, hand_eye: np.ndarray, offset: np.ndarray, steps=None):
    """Vicon's reading of frame k: the true pose at k + lag (interpolated on SE(3) per
    component), the camera frame rotated by `hand_eye` (rotation vector [rad]) and moved by
    `offset` [m] in the camera frame. `hand_eye`, `offset`: (3,) -> R (n,3,3), t (n,3); (d,3)
    -> one truth per row, R (d,n,3,3), t (d,n,3). `steps`: lag_steps(frames) if known."""
    R = np.array([f["R"] for f in frames])
    t = np.array([f["t"] for f in frames])
    nxt = np.minimum(np.arange(len(R)) + 1, len(R) - 1)
    step = lag_steps(frames) if steps is None else steps
    R_lag = np.einsum("kij,kjl->kil", R, Rotation.from_rotvec(lag * step).as_matrix())
    t_lag = t + lag * (t[nxt] - t)
    he = Rotation.from_rotvec(np.reshape(hand_eye, (-1, 3))).as_matrix()  # (d,3,3)
    R_v = np.einsum("kij,djl->dkil", R_lag, he)
    t_v = t_lag[None] + np.einsum("dkij,dj->dki", R_v, np.reshape(offset, (-1, 3)))
    if np.ndim(hand_eye) == 1 and np.ndim(offset) == 1:
        return R_v[0], t_v[0]
    return R_v, t_v


def errors(R_est, t_est, R_true, t_true) -> tuple[np.ndarray, np.ndarray]:
    """Position [cm] and orientation [deg] errors of the frames with an estimate; R_true /
    t_true may carry a leading axis of d truths (-> (d, m) errors)."""
    R_est, t_est, R_true, t_true = (np.asarray(a, float) for a in (R_est, t_est, R_true, t_true))
    ok = np.isfinite(t_est).all(axis=1)
    pos = 100.0 * np.linalg.norm(t_est[ok] - t_true[..., ok, :], axis=-1)
    rel = np.einsum("kji,...kjl->...kil", R_est[ok], R_true[..., ok, :, :])
    # |R - I|_F = 2 sqrt(2) sin(angle / 2): exact near zero, unlike the trace
    chord = np.linalg.norm(rel - np.eye(3), axis=(-2, -1)) / (2.0 * np.sqrt(2.0))
    return pos, np.degrees(2.0 * np.arcsin(np.clip(chord, 0.0, 1.0)))


def stats(
    det: dict,
    poses: dict,
    lag: float,
    he_deg: float,
    off_cm: float,
    seed: int,
    hover: float = 1.0,
    jitter_deg: float = 0.0,
    jitter_cm: float = 0.0,
    tilt_deg: float = 0.0,
) -> dict:
    """The paper's numbers for one reading of the truth, averaged over DIRECTIONS axes (the
    hand-eye axis at `tilt_deg` from the optical axis); run 2's lag scaled by `hover` (its
    motion at 3 m relative to the simulated trajectory's); `jitter_deg`, `jitter_cm`: per-frame
    rotation and position noise of the truth (std per axis)."""
    # common random numbers: every reading sees the same axes and standard-normal jitter (of
    # `seed`), so the sweep compares readings, not draws (held_out checks other seeds)
    rng = np.random.default_rng(seed)
    he = np.radians(he_deg) * tilted_axes(rng, DIRECTIONS, tilt_deg)
    offset = 0.01 * off_cm * _axes(rng, DIRECTIONS)
    out = {}
    for run in ("run1", "run2"):
        frames = det[run]
        lag_run = lag * (hover if run == "run2" else 1.0)
        Rt, tt = truth(frames, lag_run, he, offset, det["steps"][run])  # (d, n, ...)
        rot_noise, pos_noise = rng.normal(size=(2, DIRECTIONS * len(frames), 3))
        if jitter_deg:
            jitter = Rotation.from_rotvec(np.radians(jitter_deg) * rot_noise).as_matrix()
            Rt = Rt @ jitter.reshape(Rt.shape)
        tt = tt + 0.01 * jitter_cm * pos_noise.reshape(tt.shape)
        R_est, t_est = poses[run]
        keep = np.ones(len(frames), bool)
        key = run
        if run == "run2":
            keep = np.array([f["distance"] >= AT_3M for f in frames])
            key = "run2_at_3m"
        pos, rot = errors(R_est[keep], t_est[keep], Rt[:, keep], tt[:, keep])
        s = out[key] = {}
        for name, x in (("pos", pos), ("rot", rot)):
            unit = "cm" if name == "pos" else "deg"
            for fn in ("mean", "std", "max"):
                val = float(np.mean(getattr(np, fn)(x, axis=1))) if x.size else np.nan
                s[f"{name}_{fn}_{unit}"] = val
        s["localized"] = [int(pos.shape[1]), int(keep.sum())]
    return out


def score(row: dict) -> dict:
    """Deviation of each scored number from the paper's."""
    out = {}
    for run, key in SCORED:
        ours, paper = row[run].get(key), PAPER[run][key]
        out[f"{run}.{key}"] = abs(ours / paper - 1.0) if np.isfinite(ours) else np.inf
    return out
