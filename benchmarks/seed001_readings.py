"""Issue 20 for seed 001 (001_0f8f8dae37ce6b79.txt Sec. V-A, experiment 1): under which reading
of the experiment does the seed's own pose (P3P on three markers + the fourth-marker check,
Sec. IV-C; graphloc.vision.target with refine=False and the regression prediction of Sec.
IV-A) meet the paper's errors against Vicon: run 1 position mean 1.5 cm (std 0.7), orientation
mean 1.2 deg (std 0.4); run 2 at 3 m 2.2 cm and 1.0 deg?

The rendered frames of benchmarks.seed001 (stated camera, blur, sensor noise, clutter,
occlusion episodes) are detected once; every reading re-estimates the poses from the same
detections. What the text leaves open, swept:
- the camera calibration the seed used ("any calibrated camera", Sec. III): relative focal
  error and principal-point error [px] of the intrinsics the pose is computed with;
- the Vicon body frame vs the camera frame (a hand-eye rotation offset [deg] about an axis at
  `hand_eye_tilt_deg` from the camera's optical axis) and the Vicon target frame vs the
  target's markers (a translation offset [cm]): constant errors of the ground truth, averaged
  over the axes of benchmarks.seed001_truth (random azimuths about the optical axis,
  both signs; random directions for the offset). The axis matters: the per-frame rotation the
  lag adds is mostly roll about the optical axis (the camera turns about its line of sight), so
  a hand-eye axis along it adds that roll in line with the constant angle (error std ~ the
  roll's), one across it adds it in quadrature (`rotation_why` computes both);
- the camera-Vicon time offset, as a fraction of a frame interval: the truth of frame k taken
  at k + rho along the trajectory (errors that grow with the motion: run 1 is moved by hand,
  run 2 hovers at 3 m, so run 2's lag is scaled by a `hover` factor: its motion relative to
  the simulated trajectory's, which keeps turning at 3 m);
- the truth's per-frame jitter (Vicon noise, synchronisation): rotation [deg] and position
  [cm] std per axis.
The grid is coarse first, then refined around its best (REFINE_ROUNDS, steps halved each
round). Every reading sees the same random axes and jitter draws (common random numbers), so
the sweep compares readings rather than draws; still, the best of thousands fits those draws:
`held_out` scores the chosen reading on other draws and on frames rendered anew.
Scored: the six numbers above (deviation |ours / paper - 1|; REPRODUCE_TOL of
benchmarks.seed_baselines). The maxima (12.2 cm, 4.5 deg) are single frames the paper
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
from benchmarks import seed001
from benchmarks.seed001_report import PAPER
from benchmarks.seed001_truth import lag_steps, score, stats
from benchmarks.seed_baselines import REPRODUCE_TOL
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.runner.team_run import team_graph
from graphloc.vision.target import LARGE_TARGET, TargetHypothesisConfig
from benchmarks.baselines.seed001_target import target_hypotheses

FOCAL_ERRORS = (0.0, 0.0025, 0.005, 0.01)  # relative
PRINCIPAL_ERRORS_PX = (0.0, 2.0, 5.0)
# the truth's readings: name -> coarse grid (the stated value 0 / 1 first)
TRUTH_GRID = {
    "hand_eye_deg": (0.0, 0.5, 0.75, 1.0),
    "hand_eye_tilt_deg": (0.0, 90.0),  # along / across; refined in between
    "offset_cm": (0.0, 0.5, 1.0, 1.5),
    "lag_frames": (0.0, 0.2, 0.4, 0.6),
    "hover": (1.0, 0.5, 0.25),
    "jitter_deg": (0.0,),  # raises the orientation std; refined from 0
    "jitter_cm": (0.0, 0.5),
}
REFINE_ROUNDS = 3
REFINE_STEP = {
    "hand_eye_deg": 0.125,
    "hand_eye_tilt_deg": 22.5,
    "offset_cm": 0.25,
    "lag_frames": 0.1,
    "jitter_deg": 0.1,
    "jitter_cm": 0.25,
}
BOUNDS = {"hand_eye_tilt_deg": (0.0, 90.0)}  # the refinement's limits (others: >= 0)
WHY_TILTS_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0)
RATE_HZ = 10.0  # time stamps of the graphloc log (no odometry: only the order matters)


def detections(frames1: int, frames2: int, seed: int = 1, progress: bool = True) -> dict:
    """Rendered and detected frames of both runs (as benchmarks.seed001.reproduce:
    same trajectories, clutter 3, occlusion rate 0.05): per run a list of dicts (pixels, R, t,
    distance); "steps": per run the frame-to-frame rotations (lag_steps)."""
    rng = np.random.default_rng(seed)
    out = {"run1": [], "run2": []}
    seed001.run("run 1", rng, frames1, 0.68, 1.74, False, 3, 0.05, out["run1"])
    seed001.run("run 2", rng, frames2, 1.0, 3.0, True, 3, 0.05, out["run2"])
    out["steps"] = {run: lag_steps(out[run]) for run in ("run1", "run2")}
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
        graph = team_graph(run, GraphConfig())
        res = solve(graph, "batch")
        r = run.index("climber")
        for time, row in zip(graph.node_times[r], res.estimate[r]):
            k = int(round(time * RATE_HZ))
            if 0 <= k < n and np.isfinite(row).all():
                R[k], t[k] = Rotation.from_quat(row[3:]).as_matrix(), row[:3]
    return R, t


STATED = dict(
    focal_error=0.0,
    principal_px=0.0,
    hand_eye_deg=0.0,
    hand_eye_tilt_deg=0.0,
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
        reading["hand_eye_tilt_deg"],
    )


def _row(det: dict, poses: dict, reading: dict, seed: int) -> dict:
    row = dict(reading)
    row.update(stats(det, poses, *_truth_args(reading, seed)))
    row["deviation"] = score(row)
    row["max_deviation"] = max(row["deviation"].values())
    return row


def _refined(value: float, key: str, level: int) -> list[float]:
    """`value` and its neighbours at REFINE_STEP / 2**level, within BOUNDS (default >= 0)."""
    lo, hi = BOUNDS.get(key, (0.0, np.inf))
    step = REFINE_STEP.get(key, 0.0) / 2**level
    return sorted({float(np.clip(value + d * step, lo, hi)) for d in (-1, 0, 1)})


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
            if reading["hand_eye_deg"] == 0.0 and reading["hand_eye_tilt_deg"] != 0.0:
                continue  # nor the axis without a hand-eye rotation
            rows.append({**_row(det, poses[(fe, pe)], reading, seed), "stage": "coarse"})
    seen = {tuple(r[k] for k in STATED) for r in rows}
    for level in range(REFINE_ROUNDS):  # halve the steps around the best so far
        best = min(rows, key=lambda r: r["max_deviation"])
        axes = {k: _refined(best[k], k, level) for k in TRUTH_GRID}
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


def rotation_why(det: dict, reading: dict, seed: int = 0) -> dict:
    """Why the hand-eye axis sets run 1's orientation std / mean: the rms per camera axis
    (x, y, z = optical axis) [deg] of one frame interval's rotation (what a lag of rho frames
    adds, times rho) and of the seed's own rotation error against the exact truth (the reading's
    intrinsics); run 1's orientation mean, std and their ratio and the largest deviation at
    the reading with its hand-eye axis at each of WHY_TILTS_DEG."""
    cam = reading_camera(reading["focal_error"], reading["principal_px"])
    poses = {run: seed_poses(det[run], cam) for run in ("run1", "run2")}
    out: dict = {"frame_rotation_rms_deg": {}, "p3p_rotation_rms_deg": {}, "tilt": []}
    for run in ("run1", "run2"):
        steps = np.degrees(det["steps"][run])
        out["frame_rotation_rms_deg"][run] = np.sqrt(np.mean(steps**2, axis=0)).tolist()
        R_est, _ = poses[run]
        ok = np.isfinite(R_est).all(axis=(1, 2))
        R = np.array([f["R"] for f in det[run]])[ok]
        own = Rotation.from_matrix(np.einsum("kji,kjl->kil", R_est[ok], R)).as_rotvec()
        out["p3p_rotation_rms_deg"][run] = np.degrees(np.sqrt(np.mean(own**2, axis=0))).tolist()
    for tilt in WHY_TILTS_DEG:
        row = _row(det, poses, {**reading, "hand_eye_tilt_deg": tilt}, seed)
        r1 = row["run1"]
        out["tilt"].append(
            {
                "tilt_deg": tilt,
                "rot_mean_deg": r1["rot_mean_deg"],
                "rot_std_deg": r1["rot_std_deg"],
                "std_over_mean": r1["rot_std_deg"] / r1["rot_mean_deg"],
                "max_deviation": row["max_deviation"],
            }
        )
    return out


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


HELD_OUT_DRAWS = 10  # other seeds of the chosen reading's random axes and jitter


def held_out(det: dict, reading: dict, frames1: int, frames2: int, seed: int) -> dict:
    """The chosen reading away from the draws it was chosen on (the sweep picks the best of
    thousands, a lucky draw among them): its largest deviation under HELD_OUT_DRAWS other seeds
    of the random axes and jitter, and on frames rendered anew (render seed + 1)."""
    cam = reading_camera(reading["focal_error"], reading["principal_px"])
    poses = {run: seed_poses(det[run], cam) for run in ("run1", "run2")}
    draws = [_row(det, poses, reading, s)["max_deviation"] for s in range(1, HELD_OUT_DRAWS + 1)]
    fresh = detections(frames1, frames2, seed + 1)
    poses = {run: seed_poses(fresh[run], cam) for run in ("run1", "run2")}
    row = _row(fresh, poses, reading, 0)
    return {
        "draws": draws,
        "rendered": {
            "seed": seed + 1,
            "deviation": row["deviation"],
            "max": row["max_deviation"],
            "roll_rms_deg": [_roll_rms(d) for d in (det, fresh)],  # run 1: sweep's, anew
        },
    }


def _roll_rms(det: dict) -> float:
    """Run 1's rms rotation about the optical axis per frame interval [deg]."""
    return float(np.degrees(np.sqrt(np.mean(det["steps"]["run1"][:, 2] ** 2))))


def run_all(frames1: int, frames2: int, choose, seed: int = 1, progress: bool = True) -> dict:
    """Detections, the sweep, its choice (`choose`: benchmarks.seed_baselines.choose)
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
        "refine_rounds": REFINE_ROUNDS,
        "evidence": evidence(rows),
        "max_deviations": [r["max_deviation"] for r in rows],
        "rows": stated + rest[:KEEP_ROWS],  # the stated reading and the best KEEP_ROWS
        "choice": {**choice.__dict__},
        "why": rotation_why(det, best),
        "held_out": held_out(det, best, frames1, frames2, seed),
        "runs": {
            "stated": {"reading": STATED, **compare(det, STATED)},
            "reproducing": {"reading": best, **compare(det, best)},
        },
    }
