"""Issue 20 for seed 001 (001_0f8f8dae37ce6b79.txt Sec. V-A, experiment 1): under which reading
of the experiment does the seed's own pose (P3P on three markers + the fourth-marker check,
Sec. IV-C; graphloc.vision.target with refine=False and the regression prediction of Sec.
IV-A) meet the paper's errors against Vicon: run 1 position mean 1.5 cm (std 0.7), orientation
mean 1.2 deg (std 0.4); run 2 at 3 m 2.2 cm and 1.0 deg?

The rendered frames of graphloc.experiments.seed001 (stated camera, blur, sensor noise, clutter,
occlusion episodes) are detected once; every reading re-estimates the poses from the same
detections. What the text leaves open, swept:
- the camera calibration the seed used ("any calibrated camera", Sec. III): relative focal
  error and principal-point error [px] of the intrinsics the pose is computed with;
- the Vicon body frame vs the camera frame (a hand-eye rotation offset [deg]) and the Vicon
  target frame vs the target's markers (a translation offset [cm]): constant errors of the
  ground truth, each averaged over DIRECTIONS random axes;
- the camera-Vicon time offset, as a fraction of a frame interval: the truth of frame k taken
  at k + rho along the trajectory (errors that grow with the motion: run 1 is moved by hand,
  run 2 hovers at 3 m, so run 2's lag is scaled by a `hover` factor: its motion relative to
  the simulated trajectory's, which keeps turning at 3 m);
- the truth's per-frame jitter (Vicon noise, synchronisation): rotation [deg] and position
  [cm] std per axis.
The grid is coarse first, then refined around its best (REFINE_ROUNDS). Choosing the best of
thousands of readings with random axes and jitter draws favours a lucky draw: the chosen
reading's deviations are an optimistic estimate.
Scored: the six numbers above (deviation |ours / paper - 1|; REPRODUCE_TOL of
graphloc.experiments.seed_baselines). The maxima (12.2 cm, 4.5 deg) are single frames the paper
attributes to three visible markers; they are reported beside, not scored.

graphloc at a reading: the same detections written as a graphloc log (camera = the reading's
intrinsics) through the front door (graphloc.datasets.open_run -> team graph -> batch LM), its
poses scored against the same perturbed truth.
"""

from __future__ import annotations

import itertools
import tempfile
from pathlib import Path

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.cameras import PinholeCamera
from graphloc.datasets import open_run
from graphloc.datasets.breitenmoser import CENTROID_SIGMA_PX, seed001_camera
from graphloc.datasets.camera_track import CameraTrackLog, write_camera_track
from graphloc.experiments import seed001
from graphloc.experiments.seed001_report import PAPER
from graphloc.experiments.seed_baselines import REPRODUCE_TOL
from graphloc.pipelines.team_graph import GraphConfig, build_graph, solve
from graphloc.vision.target import LARGE_TARGET, TargetHypothesisConfig, target_hypotheses

FOCAL_ERRORS = (0.0, 0.005, 0.01)  # relative
PRINCIPAL_ERRORS_PX = (0.0, 2.0, 5.0)
# the truth's readings: name -> coarse grid (the stated value 0 / 1 first)
TRUTH_GRID = {
    "hand_eye_deg": (0.0, 0.5, 0.75, 1.0),
    "offset_cm": (0.0, 0.5, 1.0, 1.5),
    "lag_frames": (0.0, 0.2, 0.4, 0.6),
    "hover": (1.0, 0.5, 0.25),
    "jitter_deg": (0.0, 0.2),
    "jitter_cm": (0.0, 0.5),
}
REFINE_ROUNDS = 2
REFINE_STEP = {
    "hand_eye_deg": 0.125,
    "offset_cm": 0.25,
    "lag_frames": 0.1,
    "jitter_deg": 0.1,
    "jitter_cm": 0.25,
}
DIRECTIONS = 4  # random axes per offset magnitude (seeded), statistics averaged
RATE_HZ = 10.0  # time stamps of the graphloc log (no odometry: only the order matters)
AT_3M = 2.8  # run 2 frames at >= this distance count as "at 3 m" (as seed001.summarize)
SCORED = (
    ("run1", "pos_mean_cm"),
    ("run1", "pos_std_cm"),
    ("run1", "rot_mean_deg"),
    ("run1", "rot_std_deg"),
    ("run2_at_3m", "pos_mean_cm"),
    ("run2_at_3m", "rot_mean_deg"),
)


def detections(frames1: int, frames2: int, seed: int = 1, progress: bool = True) -> dict:
    """Rendered and detected frames of both runs (as graphloc.experiments.seed001.reproduce:
    same trajectories, clutter 3, occlusion rate 0.05): per run a list of dicts (pixels, R, t,
    distance)."""
    rng = np.random.default_rng(seed)
    out = {"run1": [], "run2": []}
    seed001.run("run 1", rng, frames1, 0.68, 1.74, False, 3, 0.05, out["run1"])
    seed001.run("run 2", rng, frames2, 1.0, 3.0, True, 3, 0.05, out["run2"])
    return out


def reading_camera(focal_error: float, principal_px: float) -> PinholeCamera:
    c = seed001_camera()
    f = 1.0 + focal_error
    return PinholeCamera(
        c.fx * f, c.fy * f, c.cx + principal_px, c.cy + principal_px, c.width, c.height
    )


def seed_poses(frames: list, camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """The seed's pose per frame (R (n,3,3), t (n,3), NaN where none): P3P + fourth-marker
    check, near-ties resolved by the regression prediction from its own last K_R poses."""
    n = len(frames)
    R, t = np.full((n, 3, 3), np.nan), np.full((n, 3), np.nan)
    history: list[tuple[int, gtsam.Pose3]] = []
    cfg = TargetHypothesisConfig(refine=False)
    for k, f in enumerate(frames):
        if history and k - history[-1][0] > seed001.MAX_COAST:
            history.clear()
        predicted = None
        if len(history) >= seed001.K_R:
            predicted = seed001.predict_pose(
                [p for _, p in history], k_R=seed001.K_R, times=[i for i, _ in history], t_next=k
            )
        if len(f["pixels"]) < 3:
            continue
        cands = target_hypotheses(
            f["pixels"], camera, LARGE_TARGET, cfg, predicted=predicted, time=float(k)
        )
        best = seed001.pick(cands, predicted) if len(cands) else None
        if best is None:
            continue
        R[k], t[k] = cands.R[best], cands.t[best]
        history.append((k, gtsam.Pose3(gtsam.Rot3(R[k]), t[k])))
        del history[: -seed001.K_R]
    return R, t


def graphloc_poses(frames: list, camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """graphloc's batch estimate of the camera per frame (NaN where none) from the same
    detections, through a graphloc log and the front door (identical markers: the
    HypothesisTracker decides among the P3P candidate sets)."""
    n = len(frames)
    pixels = np.full((n, len(LARGE_TARGET.points), 2), np.nan)
    for k, f in enumerate(frames):
        m = min(len(f["pixels"]), len(LARGE_TARGET.points))
        pixels[k, :m] = f["pixels"][:m]
    log = CameraTrackLog(
        name="seed001-readings",
        times=np.arange(n) / RATE_HZ,
        R_wc=np.array([f["R"] for f in frames]),
        t_wc=np.array([f["t"] for f in frames]),
        layout=LARGE_TARGET.points,
        pixels=pixels,
        camera=camera,
        pixel_sigma=CENTROID_SIGMA_PX,
        odometry=[],
        odometry_cov=[],
        observer="climber",
        target="target",
        identical_markers=True,
    )
    R, t = np.full((n, 3, 3), np.nan), np.full((n, 3), np.nan)
    with tempfile.TemporaryDirectory() as tmp:
        write_camera_track(log, Path(tmp))
        run = open_run(Path(tmp))
        graph = build_graph(run, GraphConfig())
        res = solve(graph, "batch")
        r = run.index("climber")
        for time, row in zip(graph.node_times[r], res.estimate[r]):
            k = int(round(time * RATE_HZ))
            if 0 <= k < n and np.isfinite(row).all():
                R[k], t[k] = Rotation.from_quat(row[3:]).as_matrix(), row[:3]
    return R, t


def _axes(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def truth(frames: list, lag: float, hand_eye: np.ndarray, offset: np.ndarray):
    """Vicon's reading of frame k: the true pose at k + lag (interpolated on SE(3) per
    component), the camera frame rotated by `hand_eye` (rotation vector [rad]) and moved by
    `offset` [m] in the camera frame."""
    R = np.array([f["R"] for f in frames])
    t = np.array([f["t"] for f in frames])
    nxt = np.minimum(np.arange(len(R)) + 1, len(R) - 1)
    step = Rotation.from_matrix(np.einsum("kji,kjl->kil", R, R[nxt])).as_rotvec()
    R_lag = np.einsum("kij,kjl->kil", R, Rotation.from_rotvec(lag * step).as_matrix())
    t_lag = t + lag * (t[nxt] - t)
    R_v = R_lag @ Rotation.from_rotvec(hand_eye).as_matrix()
    return R_v, t_lag + R_v @ offset


def errors(R_est, t_est, R_true, t_true) -> tuple[np.ndarray, np.ndarray]:
    """Position [cm] and orientation [deg] errors of the frames with an estimate."""
    R_est, t_est, R_true, t_true = (np.asarray(a, float) for a in (R_est, t_est, R_true, t_true))
    ok = np.isfinite(t_est).all(axis=1)
    pos = 100.0 * np.linalg.norm(t_est[ok] - t_true[ok], axis=1)
    rel = np.einsum("kji,kjl->kil", R_est[ok], R_true[ok])
    rot = np.degrees(np.linalg.norm(Rotation.from_matrix(rel).as_rotvec(), axis=1))
    return pos, rot


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
) -> dict:
    """The paper's numbers for one reading of the truth, averaged over DIRECTIONS axes; run 2's
    lag scaled by `hover` (its motion at 3 m relative to the simulated trajectory's);
    `jitter_deg`, `jitter_cm`: per-frame rotation and position noise of the truth (std per
    axis)."""
    rng = np.random.default_rng(
        [
            seed,
            int(1e3 * he_deg),
            int(1e3 * off_cm),
            int(1e3 * lag),
            int(1e3 * hover),
            int(1e3 * jitter_deg),
        ]
    )
    acc: dict = {}
    for a, b in zip(_axes(rng, DIRECTIONS), _axes(rng, DIRECTIONS)):
        for run in ("run1", "run2"):
            frames = det[run]
            lag_run = lag * (hover if run == "run2" else 1.0)
            Rt, tt = truth(frames, lag_run, np.radians(he_deg) * a, 0.01 * off_cm * b)
            if jitter_deg:
                noise = rng.normal(scale=np.radians(jitter_deg), size=(len(frames), 3))
                Rt = Rt @ Rotation.from_rotvec(noise).as_matrix()
            if jitter_cm:
                tt = tt + rng.normal(scale=0.01 * jitter_cm, size=tt.shape)
            R_est, t_est = poses[run]
            keep = np.ones(len(frames), bool)
            key = run
            if run == "run2":
                keep = np.array([f["distance"] >= AT_3M for f in frames])
                key = "run2_at_3m"
            pos, rot = errors(R_est[keep], t_est[keep], Rt[keep], tt[keep])
            s = acc.setdefault(key, {})
            for name, x in (("pos", pos), ("rot", rot)):
                unit = "cm" if name == "pos" else "deg"
                for fn in ("mean", "std", "max"):
                    val = float(getattr(np, fn)(x)) if x.size else np.nan
                    s.setdefault(f"{name}_{fn}_{unit}", []).append(val)
            s["localized"] = [int(len(pos)), int(keep.sum())]
    return {
        run: {k: (v if k == "localized" else float(np.mean(v))) for k, v in s.items()}
        for run, s in acc.items()
    }


def score(row: dict) -> dict:
    """Deviation of each scored number from the paper's."""
    out = {}
    for run, key in SCORED:
        ours, paper = row[run].get(key), PAPER[run][key]
        out[f"{run}.{key}"] = abs(ours / paper - 1.0) if np.isfinite(ours) else np.inf
    return out


STATED = dict(
    focal_error=0.0,
    principal_px=0.0,
    hand_eye_deg=0.0,
    offset_cm=0.0,
    lag_frames=0.0,
    hover=1.0,
    jitter_deg=0.0,
    jitter_cm=0.0,
)


def _truth_args(reading: dict, seed: int) -> tuple:
    """`stats`' arguments after (det, poses): the reading of the truth's errors."""
    return (
        reading["lag_frames"],
        reading["hand_eye_deg"],
        reading["offset_cm"],
        seed,
        reading["hover"],
        reading["jitter_deg"],
        reading["jitter_cm"],
    )


def _row(det: dict, poses: dict, reading: dict, seed: int) -> dict:
    row = dict(reading)
    row.update(stats(det, poses, *_truth_args(reading, seed)))
    row["deviation"] = score(row)
    row["max_deviation"] = max(row["deviation"].values())
    return row


def sweep(det: dict, seed: int = 0, progress: bool = True) -> list[dict]:
    """The coarse grid (intrinsics x TRUTH_GRID, the stated reading first), then REFINE_ROUNDS
    finer grids (REFINE_STEP, halved each round, either side) of the truth's readings around
    the best so far, at its intrinsics. Rows: the reading, the paper's numbers, their
    deviations and the largest."""
    rows = []
    intrinsics = list(itertools.product(FOCAL_ERRORS, PRINCIPAL_ERRORS_PX))
    poses = {}
    for i, (fe, pe) in enumerate(intrinsics):
        if progress:
            print(f"seed 001 readings: intrinsics {i + 1}/{len(intrinsics)}", flush=True)
        cam = reading_camera(fe, pe)
        poses[(fe, pe)] = {run: seed_poses(det[run], cam) for run in ("run1", "run2")}
        for values in itertools.product(*TRUTH_GRID.values()):
            reading = dict(focal_error=fe, principal_px=pe, **dict(zip(TRUTH_GRID, values)))
            if reading["lag_frames"] == 0.0 and reading["hover"] != 1.0:
                continue  # without a lag the hover reading changes nothing
            rows.append({**_row(det, poses[(fe, pe)], reading, seed), "stage": "coarse"})
    seen = {tuple(r[k] for k in STATED) for r in rows}
    for level in range(REFINE_ROUNDS):  # halve the steps around the best so far
        best = min(rows, key=lambda r: r["max_deviation"])
        axes = {
            k: sorted(
                {max(best[k] + d * REFINE_STEP.get(k, 0.0) / 2**level, 0.0) for d in (-1, 0, 1)}
            )
            for k in TRUTH_GRID
        }
        p = poses[(best["focal_error"], best["principal_px"])]
        for values in itertools.product(*axes.values()):
            reading = dict(
                focal_error=best["focal_error"],
                principal_px=best["principal_px"],
                **dict(zip(axes, values)),
            )
            key = tuple(reading[k] for k in STATED)
            if key not in seen:
                seen.add(key)
                rows.append({**_row(det, p, reading, seed), "stage": f"refined {level + 1}"})
    return rows


def compare(det: dict, reading: dict, seed: int = 0) -> dict:
    """Seed baseline and graphloc under one reading: the paper's numbers for each."""
    cam = reading_camera(reading["focal_error"], reading["principal_px"])
    args = _truth_args(reading, seed)
    out = {}
    for name, fn in (("seed_baseline", seed_poses), ("graphloc", graphloc_poses)):
        poses = {run: fn(det[run], cam) for run in ("run1", "run2")}
        out[name] = stats(det, poses, *args)
    return out


KEEP_ROWS = 200  # rows kept in the result (all rows' largest deviations are kept)


def evidence(rows: list[dict]) -> dict:
    """Why no reading (or which) meets all six numbers: each number's best deviation alone,
    the best largest deviation over the other five with each one left out, and how many
    readings are within REPRODUCE_TOL."""
    keys = list(rows[0]["deviation"])
    return {
        "alone": {k: min(r["deviation"][k] for r in rows) for k in keys},
        "leave_one_out": {
            k: min(max(v for kk, v in r["deviation"].items() if kk != k) for r in rows)
            for k in keys
        },
        "within_tol": sum(r["max_deviation"] <= REPRODUCE_TOL for r in rows),
    }


def reading_of(row: dict) -> dict:
    return {k: row[k] for k in STATED}


def run_all(frames1: int, frames2: int, choose, seed: int = 1, progress: bool = True) -> dict:
    """Detections, the sweep, its choice (`choose`: graphloc.experiments.seed_baselines.choose)
    and both methods at the stated and the chosen reading."""
    det = detections(frames1, frames2, seed, progress)
    rows = sweep(det, progress=progress)
    choice = choose(rows)
    best = reading_of(choice.best)
    stated = [r for r in rows if reading_of(r) == STATED]
    rest = sorted((r for r in rows if reading_of(r) != STATED), key=lambda r: r["max_deviation"])
    return {
        "frames": {"run1": frames1, "run2": frames2, "seed": seed},
        "paper": PAPER,
        "readings": len(rows),
        "evidence": evidence(rows),
        "max_deviations": [r["max_deviation"] for r in rows],
        "rows": stated + rest[:KEEP_ROWS],  # the stated reading and the best KEEP_ROWS
        "choice": {**choice.__dict__},
        "runs": {
            "stated": {"reading": STATED, **compare(det, STATED)},
            "reproducing": {"reading": best, **compare(det, best)},
        },
    }
