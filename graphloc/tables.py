"""The seeds' tables, computed: one function per table returning a plain dict (JSON-ready) and
one markdown renderer per table. Every table has the columns paper | seed baseline (ours) |
graphloc, computed on the same trials with the same noise. Runnable front-ends:
scripts/repro_seed000.py, scripts/repro_seed004.py, scripts/make_results.py and
`graphloc reproduce TABLE`.

- Seed 000 (000_05137a0a9c449be3.txt) Sec. VI-A Table I: ground triangle from
  graphloc.vision.mutual on noisy 512x512 omni pixels (C1 is the reference), camera C from P3P
  + the straight-line test (seed, Sec. IV) vs one GTSAM graph over all six cameras.
  Table II: running times measured here. Table III: graphloc.experiments.hypotheses's trials.
- Seed 004 (004_fa12d1d18dcbd0db.txt) Sec. III Table 1: RMS position error (Eq. 4) of raw P3P
  vs a GTSAM batch smoother over a short track (odometry + per-frame P3P pose factors).
"""

from __future__ import annotations

import multiprocessing as mp
import time
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from graphloc.datasets.feng_deterministic import Seed000Config, StraightLineTrials, simulate_straight_line_trials
from graphloc.baselines.straight_line import bearings_from_pixels, localize_by_straight_line
from graphloc.cameras import ParaboloidOmniCamera
from graphloc.geometry.p3p import MAX_CANDIDATES
from graphloc.geometry.so3 import skew
from graphloc.keys import pose_key
from graphloc.datasets.feng import noisy_pixels
from graphloc.vision.mutual import localize_three, render_mutual_pixels

# ---- seed 000 Table I ------------------------------------------------------------------------
PAPER_TABLE_I = {"success": 997, "trials": 1000, "C2": (1.7e-4, 6.1e-5), "C3": (1.6e-4, 5.1e-5), "C": (5.7e-4, 1.3e-4)}
PAPER_TABLE_II_MS = {"deterministic": 1.7, "update": 0.35}


@dataclass(frozen=True)
class TableIConfig:
    """Seed 000 Sec. VI-A. scale: the workspace size that turns errors into the paper's
    "relative error" ("within a relative error of 1e-3 meters out of a scale of three meters");
    success_tol [m]: also counted: trials whose three estimated positions of C are all within
    this of the truth;
    omni_max_polar [rad]: field of view of the ground robots' paraboloid cameras from the mirror
    axis; max_redraws: ground-camera orientations redrawn while a robot is outside another's
    field of view (counted); initial_rotations: graphloc starts Levenberg-Marquardt from this
    many best P3P rotations (shared_rotation_initials) and keeps the lowest graph error."""

    trials: int = 1000
    seed: int = 0
    pixel_sigma: float = 0.5
    omni_size: int = 512
    omni_max_polar: float = 2.0 * np.pi / 3.0
    scale: float = 3.0
    success_tol: float = 0.1
    max_redraws: int = 50
    initial_rotations: int = 2
    workers: int = 2

    def __post_init__(self):
        if self.trials < 1 or self.workers < 1:
            raise ValueError(f"TableIConfig: trials and workers must be >= 1, got {self.trials}, {self.workers}")
        for name in ("pixel_sigma", "scale", "success_tol"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"TableIConfig.{name} must be finite and >= 0, got {value}")


@dataclass(frozen=True)
class GroundTriangle:
    """Ground robots C1..C3 for T trials. R (T,3,3,3): camera-to-world rotations; estimated
    (T,3,3): positions from mutual bearings (C1 known: the reference), NaN where the mutual
    solver rejected the formation; R_estimated (T,3,3,3) the estimated rotations; status (T,)
    the solver's status; pixels (T,3,3,2) noisy [observer i, robot j]; bearings (T,3,3,3) their
    lifted unit bearings and bearing_sigma (T,3,3) [rad] (diagonal NaN); visible (T,): every
    robot inside the others' field of view; redrawn: orientation redraws because a robot left
    another's field of view."""

    R: np.ndarray
    estimated: np.ndarray
    R_estimated: np.ndarray
    status: np.ndarray
    pixels: np.ndarray
    bearings: np.ndarray
    bearing_sigma: np.ndarray
    visible: np.ndarray
    redrawn: int


def ground_triangle(ground: np.ndarray, config: TableIConfig, rng: np.random.Generator) -> GroundTriangle:
    """Seed 000 Sec. VI-A steps 1-2 for the ground robots: orientations with pitch, tilt, yaw
    each U(0, pi/6), mutual pixels in 512x512 paraboloid omni images (Sec. II) with N(0, 0.5)
    px noise in a random direction, then the three-robot algorithm (Sec. III-A,
    graphloc.vision.mutual) with |T_12| known; C1's pose is the reference."""
    T = len(ground)
    omni = ParaboloidOmniCamera.from_fov(config.omni_size, config.omni_max_polar)
    off = ~np.eye(3, dtype=bool)
    R = np.empty((T, 3, 3, 3))
    todo = np.arange(T)
    redrawn = 0
    for attempt in range(config.max_redraws + 1):
        R[todo] = Rotation.from_euler("xyz", rng.uniform(0.0, np.pi / 6, (todo.size * 3, 3))).as_matrix().reshape(-1, 3, 3, 3)
        _, visible = render_mutual_pixels(R[todo], ground[todo], omni)
        todo = todo[~visible[:, off].all(axis=1)]
        if todo.size == 0 or attempt == config.max_redraws:
            break
        redrawn += todo.size
    clean, seen = render_mutual_pixels(R, ground, omni)
    pixels = noisy_pixels(clean, config.pixel_sigma, rng)
    baseline = np.linalg.norm(ground[:, 1] - ground[:, 0], axis=1)
    res = localize_three(pixels, omni, baseline)
    estimated = ground[:, 0, None, :] + np.einsum("nij,nkj->nki", R[:, 0], res.t)
    R_estimated = np.einsum("nab,njbc->njac", R[:, 0], res.R)
    with np.errstate(invalid="ignore"):
        bearings = omni.pixel_to_bearing(pixels.reshape(-1, 2))[0].reshape(T, 3, 3, 3)
        sigma = angular_sigma(omni, pixels, config.pixel_sigma)
    return GroundTriangle(R, estimated, R_estimated, res.status, pixels, bearings, sigma, seen[:, off].all(axis=1), redrawn)


def _take(record, rows: np.ndarray):
    """The same frozen dataclass with every per-trial array field restricted to `rows`."""
    n = len(record.ground) if hasattr(record, "ground") else len(record.status)
    return replace(record, **{f.name: getattr(record, f.name)[rows] for f in fields(record)
                              if isinstance(getattr(record, f.name), np.ndarray) and len(getattr(record, f.name)) == n
                              and getattr(record, f.name).ndim >= 1 and f.name != "K"})


def angular_sigma(camera, pixels: np.ndarray, pixel_sigma: float, floor: float = 1e-5) -> np.ndarray:
    """Per-axis bearing sigma [rad] (...,) of pixels (...,2) with the seed's noise, N(0, sigma)
    px along a random direction (per-axis std sigma / sqrt 2), times the camera's local angle
    per pixel (finite differences of pixel_to_bearing: works for the pinhole and the omni)."""
    flat = np.asarray(pixels, dtype=float).reshape(-1, 2)
    b0, _ = camera.pixel_to_bearing(flat)
    bu, _ = camera.pixel_to_bearing(flat + (1.0, 0.0))
    bv, _ = camera.pixel_to_bearing(flat + (0.0, 1.0))
    per_px = 0.5 * (np.arccos(np.clip(np.sum(b0 * bu, axis=1), -1, 1)) + np.arccos(np.clip(np.sum(b0 * bv, axis=1), -1, 1)))
    return np.maximum(pixel_sigma / np.sqrt(2.0) * per_px, floor).reshape(np.shape(pixels)[:-1])


def shared_rotation_initials(pixels: np.ndarray, K: np.ndarray, ground: np.ndarray, R_cand: np.ndarray,
                             valid: np.ndarray, keep: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Initial values for the joint estimate (vectorized over trials and candidate rotations).
    pixels (T,3,3,2) [trial, snapshot, robot]; ground (T,3,3); R_cand (T,M,3,3) candidate
    camera rotations from P3P of any snapshot, valid (T,M). With the rotation fixed, each
    snapshot's camera centre is linear in the bearings ([f]_x R^T (X - c) = 0, least squares).
    Returns the `keep` best rotations (T,keep,3,3), centres (T,keep,3,3) and their mean squared
    angular residuals (T,keep) [rad^2] over the 9 bearings (inf: fewer valid candidates)."""
    f = bearings_from_pixels(pixels, K)  # (T,3,3,3) [trial, snapshot, robot, xyz]
    fx = skew(f)
    Rt = np.swapaxes(R_cand, -1, -2)  # (T,M,3,3)
    A = np.einsum("tsjab,tmbc->tmsjac", fx, Rt)  # (T,M,S,J,3,3)
    b = np.einsum("tmsjab,tjb->tmsja", A, ground)
    AtA = np.einsum("tmsjba,tmsjbc->tmsac", A, A)
    Atb = np.einsum("tmsjba,tmsjb->tmsa", A, b)
    with np.errstate(all="ignore"):
        c = np.linalg.solve(AtA + 1e-12 * np.eye(3), Atb[..., None])[..., 0]  # (T,M,S,3)
        pc = np.einsum("tmab,tmsjb->tmsja", Rt, ground[:, None, None, :, :] - c[:, :, :, None, :])
        cos = np.einsum("tmsja,tsja->tmsj", pc, f) / np.linalg.norm(pc, axis=-1)
    residual = np.mean(np.arccos(np.clip(cos, -1.0, 1.0)) ** 2, axis=(2, 3))
    residual = np.where(valid & np.isfinite(residual), residual, np.inf)
    best = np.argsort(residual, axis=1)[:, :keep]
    idx = np.arange(len(best))[:, None]
    return R_cand[idx, best], c[idx, best], residual[idx, best]


@dataclass(frozen=True)
class Formation:
    """Inputs of one Table I trial for graphloc's joint estimate. ground_R (3,3,3), ground_t
    (3,3): initial ground-camera poses (C1 exact, C2, C3 from graphloc.vision.mutual);
    mutual (3,3,3): omni bearings mutual[i, j] of robot j in camera i, mutual_sigma (3,3) [rad];
    baseline: |T_12|; climber (3,3,3): bearings of the ground robots in the climbing camera
    [snapshot, robot], climber_sigma (3,3) [rad]."""

    ground_R: np.ndarray
    ground_t: np.ndarray
    mutual: np.ndarray
    mutual_sigma: np.ndarray
    baseline: float
    climber: np.ndarray
    climber_sigma: np.ndarray


def joint_estimate(f: Formation, R0: np.ndarray, c0: np.ndarray, rotation_sigma: float = 1e-4,
                   reference_sigma: float = 1e-6) -> tuple[np.ndarray, np.ndarray, float]:
    """graphloc's estimate of one trial, one GTSAM graph over all six cameras (keys: ground
    robot j = pose_key(j + 1, 0), climbing-camera snapshot s = pose_key(0, s)):
    - C1: PriorFactorPose3 (the reference, seed 000 Sec. VI-A Table I "C1 (Ref)");
    - the 6 mutual omni bearings and the 9 bearings of the ground robots in the climbing
      camera: graphloc.factors.bearing.bearing_factor (Pose3 -> Pose3);
    - |T_12|: known_baseline_factor (seed 000 Problem 1 fixes the scale);
    - BetweenFactorPose3 between consecutive snapshots holding the rotation (the robot drives
      straight without turning), translation free.
    So the climbing camera's views also refine C2, C3 (the seed solves them separately).
    Levenberg-Marquardt from the mutual triangle and (R0, c0). Returns the snapshot centres
    (3,3), the ground positions (3,3) and the final graph error (NaN, NaN, inf if GTSAM
    fails, e.g. an indeterminant system)."""
    from graphloc.factors.bearing import bearing_factor, known_baseline_factor

    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for j in range(3):
        values.insert(pose_key(j + 1, 0), gtsam.Pose3(gtsam.Rot3(f.ground_R[j]), f.ground_t[j]))
        for i in range(3):
            if i != j:
                graph.add(bearing_factor(pose_key(i + 1, 0), pose_key(j + 1, 0), f.mutual[i, j], f.mutual_sigma[i, j]))
    graph.add(gtsam.PriorFactorPose3(pose_key(1, 0), gtsam.Pose3(gtsam.Rot3(f.ground_R[0]), f.ground_t[0]),
                                     gtsam.noiseModel.Isotropic.Sigma(6, reference_sigma)))
    graph.add(known_baseline_factor(pose_key(1, 0), pose_key(2, 0), f.baseline, reference_sigma))
    hold = gtsam.noiseModel.Diagonal.Sigmas(np.array([rotation_sigma] * 3 + [1e3] * 3))
    for s in range(3):
        values.insert(pose_key(0, s), gtsam.Pose3(gtsam.Rot3(R0), c0[s]))
        for j in range(3):
            graph.add(bearing_factor(pose_key(0, s), pose_key(j + 1, 0), f.climber[s, j], f.climber_sigma[s, j]))
        if s:
            graph.add(gtsam.BetweenFactorPose3(pose_key(0, s - 1), pose_key(0, s), gtsam.Pose3(), hold))
    try:
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, gtsam.LevenbergMarquardtParams()).optimize()
    except RuntimeError:  # e.g. an indeterminant system from a degenerate start: a failed trial, not a crash
        return np.full((3, 3), np.nan), np.full((3, 3), np.nan), np.inf
    return (np.stack([result.atPose3(pose_key(0, s)).translation() for s in range(3)]),
            np.stack([result.atPose3(pose_key(j + 1, 0)).translation() for j in range(3)]), graph.error(result))


def _best_joint(f: Formation, R0s, c0s, residuals) -> tuple[np.ndarray, np.ndarray, float]:
    """joint_estimate from each initial rotation (finite residual); the lowest graph error wins."""
    runs = [joint_estimate(f, R0, c0) for R0, c0, r in zip(R0s, c0s, residuals) if np.isfinite(r)]
    return min(runs, key=lambda run: run[2]) if runs else (np.full((3, 3), np.nan), np.full((3, 3), np.nan), np.inf)


def _joint_chunk(job) -> list:
    return [_best_joint(*args) for args in zip(*job)]


def formations(trials: StraightLineTrials, tri: "GroundTriangle", config: TableIConfig) -> list[Formation]:
    """One Formation per trial (rows whose ground triangle was rejected: None)."""
    from graphloc.cameras import PinholeCamera

    K = trials.K
    pinhole = PinholeCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], 640, 480)
    climber = bearings_from_pixels(trials.pixels, K)
    climber_sigma = angular_sigma(pinhole, trials.pixels, config.pixel_sigma)
    out = []
    for i in range(len(trials.ground)):
        if not np.isfinite(tri.estimated[i]).all():
            out.append(None)
            continue
        out.append(Formation(tri.R_estimated[i], tri.estimated[i], tri.bearings[i], tri.bearing_sigma[i],
                             float(np.linalg.norm(trials.ground[i, 1] - trials.ground[i, 0])), climber[i], climber_sigma[i]))
    return out


def run_joint(trials: StraightLineTrials, tri: "GroundTriangle", R_cand: np.ndarray, valid: np.ndarray,
              config: TableIConfig, progress: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """joint_estimate for every trial with an accepted ground triangle (others stay NaN),
    across `config.workers` processes in chunks. Returns climber centres (T,3,3), ground
    positions (T,3,3), graph errors (T,)."""
    T = len(trials.ground)
    positions, ground, errors = np.full((T, 3, 3), np.nan), np.full((T, 3, 3), np.nan), np.full(T, np.inf)
    forms = formations(trials, tri, config)
    rows = np.array([i for i, f in enumerate(forms) if f is not None], dtype=int)
    if rows.size == 0:
        return positions, ground, errors
    R0, c0, residual = shared_rotation_initials(trials.pixels[rows], trials.K, tri.estimated[rows], R_cand[rows], valid[rows],
                                                keep=config.initial_rotations)
    chunks = [c for c in np.array_split(np.arange(rows.size), max(1, min(rows.size, 8 * config.workers))) if c.size]
    jobs = [([forms[rows[k]] for k in c], R0[c], c0[c], residual[c]) for c in chunks]
    with mp.Pool(config.workers) if config.workers > 1 else _Serial() as pool:
        results = list(tqdm(pool.imap(_joint_chunk, jobs), total=len(jobs), desc="Table I joint (GTSAM)",
                            disable=not progress, leave=False))
    for c, out in zip(chunks, results):
        for k, (pos, g, err) in zip(c, out):
            positions[rows[k]], ground[rows[k]], errors[rows[k]] = pos, g, err
    return positions, ground, errors


class _Serial:
    """Stand-in for multiprocessing.Pool with one worker (no process start-up)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    @staticmethod
    def imap(fn, jobs):
        return map(fn, jobs)


def _classify_failures(ok: np.ndarray, ground_ok: np.ndarray, graph_error: np.ndarray) -> dict:
    """graphloc's failed trials: ground triangle rejected by the front-end; a fit as good as
    the successes' (graph error below their 99th percentile: the data cannot tell -- the P3P
    singularity the seed blames for its 3 failures); or a poor fit (a wrong basin)."""
    fail = ground_ok & ~ok
    p99 = np.percentile(graph_error[ok], 99) if ok.any() else np.inf
    return {"ground_triangle_rejected": int((~ground_ok).sum()),
            "consistent_fit_ill_conditioned": int((fail & (graph_error <= p99)).sum()),
            "poor_fit_wrong_basin": int((fail & np.isfinite(graph_error) & (graph_error > p99)).sum()),
            "optimizer_failed": int((fail & ~np.isfinite(graph_error)).sum()), "success_graph_error_p99": float(p99)}


def _nearest_candidate(cand_t: np.ndarray, cand_valid: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """(T,3) index of the P3P candidate (T,3,K,3) nearest each position (T,3,3)."""
    d = np.linalg.norm(cand_t - positions[:, :, None, :], axis=3)
    return np.argmin(np.where(cand_valid, d, np.inf), axis=2)


def _rel_stats(errors: np.ndarray, scale: float) -> dict:
    e = errors[np.isfinite(errors)]
    if e.size == 0:
        return {"mean": None, "std": None, "abs_mean_m": None, "abs_median_m": None, "n": 0}
    return {"mean": float(e.mean() / scale), "std": float(e.std() / scale), "abs_mean_m": float(e.mean()),
            "abs_median_m": float(np.median(e)), "n": int(e.size)}


def table_i(config: TableIConfig = TableIConfig(), progress: bool = True) -> dict:
    """Seed 000 Table I on `config.trials` trials (see the module docstring). Returns success
    counts and relative errors (mean, std over successful trials) of C2, C3 and C for the seed
    baseline and graphloc, the paper's numbers, timings and the failure breakdown."""
    t_start = time.perf_counter()
    sim = Seed000Config(pixel_sigma=config.pixel_sigma)
    # formations where some robot stays outside another's omni field of view whatever the
    # orientation are redrawn (as datasets/feng_deterministic.py redraws trials where C cannot see them)
    pool = simulate_straight_line_trials(int(1.1 * config.trials) + 10, seed=config.seed, config=sim)
    tri = ground_triangle(pool.ground, config, np.random.default_rng([config.seed, 1]))
    rows = np.flatnonzero(tri.visible)[: config.trials]
    if rows.size < config.trials:
        raise ValueError(f"seed000 Table I: only {rows.size} of {len(pool.ground)} formations are mutually visible "
                         f"with omni_max_polar={config.omni_max_polar:.3f}")
    unobservable = int((~tri.visible[: rows[-1] + 1]).sum())
    trials, tri = _take(pool, rows), _take(tri, rows)
    ground_ok = np.isfinite(tri.estimated).all(axis=(1, 2))
    err_ground = np.linalg.norm(tri.estimated - trials.ground, axis=2)  # (T,3), NaN where rejected
    ok_rows = np.flatnonzero(ground_ok)

    # seed baseline: P3P per snapshot + the straight-line test (Sec. IV), batched over the
    # trials whose ground triangle was accepted (the others count as failures of both columns)
    t0 = time.perf_counter()
    choice = localize_by_straight_line(trials.pixels[ok_rows], trials.K, tri.estimated[ok_rows])
    seed_time = time.perf_counter() - t0
    T = config.trials
    seed_pos = np.full((T, 3, 3), np.nan)
    seed_pos[ok_rows] = choice.chosen_positions()
    cand_t = np.zeros((T, 3, MAX_CANDIDATES, 3))
    cand_valid = np.zeros((T, 3, MAX_CANDIDATES), dtype=bool)
    R_cand = np.broadcast_to(np.eye(3), (T, 3 * MAX_CANDIDATES, 3, 3)).copy()
    cand_t[ok_rows] = choice.candidates.t_wc.reshape(-1, 3, MAX_CANDIDATES, 3)
    cand_valid[ok_rows] = choice.candidates.valid.reshape(-1, 3, MAX_CANDIDATES)
    R_cand[ok_rows] = choice.candidates.R_wc.reshape(-1, 3 * MAX_CANDIDATES, 3, 3)

    # graphloc: joint GTSAM estimate with the shared rotation, from the best P3P rotations
    valid = cand_valid.reshape(-1, 3 * MAX_CANDIDATES)
    t0 = time.perf_counter()
    joint_pos, joint_ground, joint_graph_error = run_joint(trials, tri, R_cand, valid, config, progress)
    joint_time = time.perf_counter() - t0

    truth_to_candidates = np.where(cand_valid, np.linalg.norm(cand_t - trials.positions[:, :, None, :], axis=3), np.inf)
    nearest_pseudo = np.sort(truth_to_candidates, axis=2)[:, :, 1]  # (T,3) distance of the closest wrong solution

    def success(pos: np.ndarray) -> np.ndarray:
        """The paper's "correct result": in all three snapshots the estimate is closer to the
        truth than any pseudo P3P solution is. For a method that picks candidates (the seed)
        this is exactly "picked the genuine one"; a refined estimate may be better than the
        genuine candidate itself."""
        err = np.linalg.norm(pos - trials.positions, axis=2)
        return ground_ok & (np.nan_to_num(err, nan=np.inf) < nearest_pseudo).all(axis=1)

    def outcome(pos: np.ndarray, ground_est: np.ndarray, ok: np.ndarray, common: np.ndarray) -> dict:
        err_ground = np.linalg.norm(ground_est - trials.ground, axis=2)
        err = np.linalg.norm(pos - trials.positions, axis=2)
        within = ground_ok & (np.nan_to_num(err, nan=np.inf).max(axis=1) < config.success_tol)

        def stats(mask):
            return {"C2": _rel_stats(err_ground[mask, 1], config.scale), "C3": _rel_stats(err_ground[mask, 2], config.scale),
                    "C": _rel_stats(err[mask].ravel(), config.scale)}

        return {"success": int(ok.sum()), "within_tol": int(within.sum()), **stats(ok), "common_trials": stats(common)}

    seed_ok, joint_ok = success(seed_pos), success(joint_pos)
    common = seed_ok & joint_ok

    # the genuine P3P candidate with the *true* ground positions: the front-end's noise floor
    floor = localize_by_straight_line(trials.pixels, trials.K, trials.ground)
    floor_t = floor.candidates.t_wc.reshape(-1, 3, MAX_CANDIDATES, 3)
    floor_d = np.where(floor.candidates.valid.reshape(-1, 3, MAX_CANDIDATES),
                       np.linalg.norm(floor_t - trials.positions[:, :, None, :], axis=3), np.inf).min(axis=2)

    return {
        "table": "seed000-table1", "config": asdict(config), "trials": config.trials, "paper": PAPER_TABLE_I,
        "common_successes": int(common.sum()),
        "graphloc_failures": _classify_failures(joint_ok, ground_ok, joint_graph_error),
        "seed_baseline": {**outcome(seed_pos, tri.estimated, seed_ok, common),
                          "line_error_median_m": float(np.nanmedian(np.where(np.isfinite(choice.error), choice.error, np.nan))),
                          "second_line_error_median_m": float(np.nanmedian(
                              np.where(np.isfinite(choice.second_error), choice.second_error, np.nan)))},
        "graphloc": {**outcome(joint_pos, joint_ground, joint_ok, common), "graph_error_median": float(np.median(joint_graph_error[np.isfinite(joint_graph_error)]))},
        "failures": {"ground_triangle_rejected": int((~ground_ok).sum()),
                     "ground_status": {str(s): int(n) for s, n in zip(*np.unique(tri.status, return_counts=True))},
                     "ground_orientation_redraws": tri.redrawn,
                     "formations_redrawn_not_mutually_visible": unobservable, "camera_trials_redrawn": trials.redrawn},
        "evidence": {"genuine_p3p_error_true_ground_median_m": float(np.median(floor_d)),
                     "genuine_p3p_error_true_ground_p90_m": float(np.percentile(floor_d, 90)),
                     "ground_error_median_m": float(np.nanmedian(err_ground[:, 1:]))},
        "timing": {"seed_batched_s": seed_time, "graphloc_s": joint_time, "total_s": time.perf_counter() - t_start},
    }


# ---- seed 000 Table III / Fig. 6 (trials of graphloc.experiments.hypotheses) ---------------------
@dataclass(frozen=True)
class TableIIIConfig:
    """Seed 000 Sec. VI-B: `runs` runs per (ceiling, curve) cell (paper: 100). The remaining
    fields are graphloc.experiments.hypotheses's options (same defaults): tracker K, belief Def. 2
    lambda, straight-line snapshot spacing / commit threshold, pixel noise [px], seed offset."""

    runs: int = 100
    workers: int = 2
    max_hypotheses: int = 8
    lam: float = 5.0
    line_spacing: int = 10
    line_max_error: float = 0.05
    pixel_sigma: float = 0.5
    seed_offset: int = 0

    def __post_init__(self):
        if self.runs < 1 or self.workers < 1:
            raise ValueError(f"TableIIIConfig: runs and workers must be >= 1, got {self.runs}, {self.workers}")


def bench_hypotheses():
    """The Table III trials (graphloc.experiments.hypotheses: `trial`, `summarize`,
    `make_engine`, `odometry_steps`, CELLS -- one implementation for the script and the tables)."""
    from graphloc.experiments import hypotheses

    return hypotheses


def seed001_experiment(out_dir: Path, quick: bool = False) -> str:
    """Seed 001 experiment 1 (graphloc.experiments.seed001, rendered frames; writes its JSON
    and PNG to out_dir); returns its markdown table."""
    from graphloc.experiments import seed001

    frames = {"frames1": 60, "frames2": 40} if quick else {}
    table = seed001.markdown(seed001.reproduce(out_dir, **frames)["summary"])
    return ("### Seed 001 experiment 1: pose error vs the paper (scripts/repro_seed001.py, rendered frames)\n\n"
            + table + f"\n\nPlot: {Path(out_dir).name}/repro_seed001_error_vs_distance.png.\n")


def _bench_args(config: TableIIIConfig):
    import argparse

    return argparse.Namespace(**{k: v for k, v in asdict(config).items() if k not in ("runs", "workers")})


def table_iii(config: TableIIIConfig = TableIIIConfig(), progress: bool = True) -> dict:
    """Seed 000 Table III: mean updates to converge per cell for every method of
    bench_hypotheses (same simulated runs for all), plus the per-update latencies used by
    Table II."""
    bench = bench_hypotheses()
    args = _bench_args(config)
    jobs = [(ceiling, curve, i, args) for ceiling, curve in bench.CELLS for i in range(config.runs)]
    t0 = time.perf_counter()
    with mp.Pool(config.workers) if config.workers > 1 else _Serial() as pool:
        trials = list(tqdm(pool.imap_unordered(bench.trial, jobs) if config.workers > 1 else pool.imap(bench.trial, jobs),
                           total=len(jobs), desc="Table III runs", disable=not progress, leave=False))
    cells = bench.summarize(trials)
    beaten = {name: _fewer_updates(cell, "mean_updates_to_converge") for name, cell in cells.items()}
    beaten_correct = {name: _fewer_updates(cell, "mean_updates_to_correct_lock") for name, cell in cells.items()}
    return {"table": "seed000-table3", "config": asdict(config), "cells": cells,
            "graphloc_fewer_updates_than_paper_and_belief": beaten,
            "graphloc_fewer_updates_to_correct_lock_than_paper_and_belief": beaten_correct,
            "target_met": all(beaten.values()), "target_met_correct_lock": all(beaten_correct.values()),
            "wall_time_s": time.perf_counter() - t0}


def _fewer_updates(cell: dict, key: str) -> bool:
    """graphloc's tracker needs fewer mean updates (`key`) than the paper and both belief-vector
    definitions (a belief vector that never gets there in any run counts as slower)."""
    mine = cell["tracker"][key]
    others = [cell["paper_table_iii"]] + [cell[m][key] for m in ("belief_def1", "belief_def2")]
    return mine is not None and all(o is None or mine < o for o in others)


def fig6_series(updates: int = 40, seed_offset: int = 0, config: TableIIIConfig = TableIIIConfig()) -> dict:
    """Seed 000 Fig. 6 style: probability of the genuine candidate vs update for one run of
    each cell, belief vector (Def. 1, seed Sec. V-B) vs graphloc's HypothesisTracker, on
    the same run (bench_hypotheses' simulation and engines)."""
    from graphloc.datasets.feng import FengProbabilisticConfig, FengProbabilisticScenario

    bench = bench_hypotheses()
    args = _bench_args(config)
    out = {}
    for cell_index, (ceiling, curve) in enumerate(bench.CELLS):
        seed = 1000 * cell_index + seed_offset
        sim = FengProbabilisticConfig(ceiling=ceiling, curve=curve, seed=seed, pixel_sigma=config.pixel_sigma)
        run = FengProbabilisticScenario.simulate(sim)
        odometry = bench.odometry_steps(run, sim)
        series = {}
        for method in ("belief_def1", "tracker"):
            engine = bench.make_engine(method, ceiling, args, seed)
            probs = []
            for cands, odo in list(zip(run.candidates, odometry))[:updates]:
                d = engine.update(cands, odo)
                g = cands.meta.get("genuine", -1)
                probs.append(float(d.probabilities[g]) if 0 <= g < len(d.probabilities) else float("nan"))
            series[method] = probs
        out[f"{ceiling}/{curve}"] = series
    return out


def table_ii(table3: dict | None = None, samples: int = 100, seed: int = 0, table1: dict | None = None) -> dict:
    """Seed 000 Table II on this machine: the deterministic algorithm per trial, one trial per
    call (seed: mutual triangle + P3P on three snapshots + straight-line test; graphloc: the
    same front-end + the joint GTSAM estimate), and one probabilistic update (mean latency of
    belief Def. 1 / particle filter / HypothesisTracker from the Table III runs). Median over
    `samples` trials; the simulation itself is not timed."""
    config = TableIConfig(trials=samples, seed=seed, workers=1)
    trials = simulate_straight_line_trials(samples, seed=seed)
    omni = ParaboloidOmniCamera.from_fov(config.omni_size, config.omni_max_polar)
    tri = ground_triangle(trials.ground, config, np.random.default_rng([seed, 1]))
    forms = formations(trials, tri, config)
    seed_ms, joint_ms = [], []
    for i in range(samples):
        if forms[i] is None:
            continue
        sl = slice(i, i + 1)
        t0 = time.perf_counter()
        res = localize_three(tri.pixels[sl], omni, forms[i].baseline)
        ground = trials.ground[sl, 0, None, :] + np.einsum("nij,nkj->nki", tri.R[sl, 0], res.t)
        choice = localize_by_straight_line(trials.pixels[sl], trials.K, ground)
        t1 = time.perf_counter()
        R0, c0, r = shared_rotation_initials(trials.pixels[sl], trials.K, ground, choice.candidates.R_wc.reshape(1, -1, 3, 3),
                                             choice.candidates.valid.reshape(1, -1))
        _best_joint(forms[i], R0[0], c0[0], r[0])
        t2 = time.perf_counter()
        seed_ms.append(1e3 * (t1 - t0))
        joint_ms.append(1e3 * (t2 - t0))
    n = len(seed_ms)
    from graphloc.factors.bearing import bearing_linearize_cost
    out = {"table": "seed000-table2", "paper_ms": PAPER_TABLE_II_MS, "samples": n,
           "deterministic_ms": {"seed_baseline": float(np.median(seed_ms)), "graphloc": float(np.median(joint_ms))},
           "bearing_custom_factor_linearize": bearing_linearize_cost(500)}
    if table1 is not None:  # vectorized over all Table I trials, per trial
        out["deterministic_batched_ms"] = {"seed_baseline": 1e3 * table1["timing"]["seed_batched_s"] / table1["trials"],
                                           "graphloc": 1e3 * table1["timing"]["graphloc_s"] / table1["trials"]}
    if table3 is not None:
        cells = table3["cells"].values()
        out["update_ms"] = {m: float(np.mean([c[m]["mean_latency_ms"] for c in cells]))
                            for m in ("belief_def1", "belief_def2", "particle_filter", "tracker")}
    return out


# ---- seed 004 Table 1 ------------------------------------------------------------------------
# (focal mm, pixel noise variance) -> (mean, sigma) of the P3P position error [m], seed 004 Table 1
PAPER_SEED004_TABLE_1 = {(16.0, 3.0): (0.0815, 0.0407), (26.0, 3.0): (0.0522, 0.0260), (36.0, 3.0): (0.0370, 0.0178),
                         (16.0, 5.0): (0.1072, 0.0551), (26.0, 5.0): (0.0641, 0.0334), (36.0, 5.0): (0.0481, 0.0230),
                         (16.0, 10.0): (0.1447, 0.0712), (26.0, 10.0): (0.0917, 0.0462), (36.0, 10.0): (0.0674, 0.0338)}


def smooth_track(cand_R: np.ndarray, cand_t: np.ndarray, cand_cov: np.ndarray, have: np.ndarray, odometry: list,
                 odometry_noise: float, odometry_rot_sigma: float) -> np.ndarray:
    """graphloc's estimate of one track (seed 004 Table 1 column): one batch Session (GTSAM
    Levenberg-Marquardt) over the F camera poses with a PriorFactorPose3 per frame from its
    genuine P3P candidate (R (F,3,3), t (F,3), first-order covariance (F,6,6); frames with
    have[f] False get none) and a BetweenFactorPose3 per odometry step (covariance of
    graphloc.datasets.feng.odometry_covariance). Returns the smoothed centres (F,3)."""
    from graphloc.datasets.feng import odometry_covariance
    from graphloc.session import Session, SessionConfig

    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    F = len(cand_t)
    anchor = int(np.argmax(have))
    pose = gtsam.Pose3(gtsam.Rot3(cand_R[anchor]), cand_t[anchor])
    initial = [None] * F
    initial[anchor] = pose
    for f in range(anchor - 1, -1, -1):
        initial[f] = initial[f + 1].compose(odometry[f].inverse())
    for f in range(anchor + 1, F):
        initial[f] = initial[f - 1].compose(odometry[f - 1])
    for f in range(F):
        values.insert(pose_key(0, f), initial[f])
        if have[f]:
            graph.add(gtsam.PriorFactorPose3(pose_key(0, f), gtsam.Pose3(gtsam.Rot3(cand_R[f]), cand_t[f]),
                                             gtsam.noiseModel.Gaussian.Covariance(cand_cov[f])))
        if f:
            cov = odometry_covariance(odometry[f - 1], odometry_noise, odometry_rot_sigma)
            graph.add(gtsam.BetweenFactorPose3(pose_key(0, f - 1), pose_key(0, f), odometry[f - 1],
                                               gtsam.noiseModel.Gaussian.Covariance(cov)))
    session = Session(SessionConfig(mode="batch"))
    session.add(graph, values)
    est = session.estimate()
    return np.stack([est.atPose3(pose_key(0, f)).translation() for f in range(F)])


def _smooth_chunk(job) -> np.ndarray:
    cand_R, cand_t, cand_cov, have, odometry, noise, rot = job
    return np.stack([smooth_track(*args, noise, rot) for args in zip(cand_R, cand_t, cand_cov, have, odometry)])


def _error_stats(err: np.ndarray) -> dict:
    e = err[np.isfinite(err)]
    return {"rms": float(np.sqrt(np.mean(e ** 2))), "mean": float(e.mean()), "std": float(e.std()), "n": int(e.size)}


def seed004_cell(config, workers: int = 1) -> dict:
    """One cell of seed 004 Table 1: raw P3P (genuine candidate) vs the smoothed track, same
    runs. `config` is a graphloc.datasets.kaushik.KaushikConfig."""
    from graphloc.geometry.resection import resection_covariance
    from graphloc.datasets.kaushik import simulate

    runs = simulate(config)
    N, F = runs.genuine.shape
    have = runs.genuine >= 0
    flat = np.flatnonzero(have.ravel())
    gidx = runs.genuine.ravel()[flat]
    R = np.zeros((N * F, 3, 3))
    R[:] = np.eye(3)
    t = np.zeros((N * F, 3))
    cov = np.broadcast_to(np.eye(6), (N * F, 6, 6)).copy()
    R[flat], t[flat] = runs.candidates.R_wc[flat, gidx], runs.candidates.t_wc[flat, gidx]
    sigma = float(np.sqrt(config.noise_variance))
    cov[flat] = resection_covariance(config.camera(), R[flat], t[flat], np.broadcast_to(runs.leds, (flat.size, 3, 3)),
                                     sigma)
    R, t, cov = R.reshape(N, F, 3, 3), t.reshape(N, F, 3), cov.reshape(N, F, 6, 6)
    chunks = [c for c in np.array_split(np.arange(N), max(1, min(N, 4 * workers))) if c.size]
    usable = have.any(axis=1)
    jobs = [(R[c][usable[c]], t[c][usable[c]], cov[c][usable[c]], have[c][usable[c]],
             [runs.odometry[i] for i in c if usable[i]], config.odometry_noise, config.odometry_rot_sigma) for c in chunks]
    smoothed = np.full((N, F, 3), np.nan)
    with mp.Pool(workers) if workers > 1 else _Serial() as pool:
        for c, out in zip(chunks, pool.imap(_smooth_chunk, jobs)):
            if len(out):
                smoothed[c[usable[c]]] = out
    raw_err = np.where(have, runs.genuine_error, np.nan)
    smooth_err = np.linalg.norm(smoothed - runs.t_wc, axis=2)
    paper = PAPER_SEED004_TABLE_1.get((float(config.focal_mm), float(config.noise_variance)))
    # evidence: P3P is singular when the camera is on the danger cylinder (through the LEDs,
    # axis normal to their plane; radius = circumradius) -- overhead views straddle it
    radius = np.linalg.norm(runs.leds[0] - runs.leds.mean(axis=0))
    offset = np.linalg.norm(runs.t_wc[..., :2] - runs.leds.mean(axis=0)[:2], axis=2)
    far = np.abs(offset - radius) > 0.5 * radius
    return {"focal_mm": config.focal_mm, "noise_variance": config.noise_variance, "runs": N, "frames": F,
            "paper": None if paper is None else {"mean": paper[0], "std": paper[1]},
            "seed_baseline_raw_p3p": _error_stats(raw_err), "graphloc_smoothed": _error_stats(smooth_err),
            "frames_without_candidate": int((~have).sum()),
            "raw_p3p_rms_far_from_danger_cylinder": _error_stats(raw_err[far])["rms"] if far.any() else None,
            "raw_p3p_rms_near_danger_cylinder": _error_stats(raw_err[~far])["rms"] if (~far).any() else None,
            "candidates_per_frame_mean": float(runs.candidates.valid.sum(axis=1).mean())}


def seed004_table_1(runs: int = 1000, frames: int = 10, seed: int = 0, workers: int = 2, progress: bool = True) -> dict:
    """Seed 004 Table 1: every (focal, noise) cell with `runs` tracks of `frames` updates."""
    from graphloc.datasets.kaushik import FOCALS_MM, NOISE_VARIANCES, KaushikConfig

    t0 = time.perf_counter()
    cells = []
    grid = [(v, f) for v in NOISE_VARIANCES for f in FOCALS_MM]
    for i, (variance, focal) in enumerate(tqdm(grid, desc="seed 004 Table 1 cells", disable=not progress, leave=False)):
        cfg = KaushikConfig(focal_mm=focal, noise_variance=variance, runs=runs, frames=frames, seed=seed + i)
        cells.append(seed004_cell(cfg, workers))
    below = all(c["graphloc_smoothed"]["rms"] < c["seed_baseline_raw_p3p"]["rms"] for c in cells)
    return {"table": "seed004-table1", "runs": runs, "frames": frames, "seed": seed,
            "setup": {k: v for k, v in asdict(KaushikConfig()).items() if k not in ("focal_mm", "noise_variance", "runs", "frames", "seed")},
            "cells": cells, "target_smoothed_below_raw_in_all_cells": below, "wall_time_s": time.perf_counter() - t0}


# ---- markdown ---------------------------------------------------------------------------------
def _f(x, spec: str = ".2e") -> str:
    return "n/a" if x is None else format(x, spec)


def markdown_table_i(r: dict) -> str:
    p, s, g = r["paper"], r["seed_baseline"], r["graphloc"]
    gf, fl = r["graphloc_failures"], r["failures"]
    lines = [f"### Seed 000 Table I: relative position error ({r['trials']} trials, error / {r['config']['scale']:g} m)", "",
             "| quantity | paper | seed baseline (ours: P3P + straight-line test) | graphloc (joint GTSAM, shared rotation) |",
             "|---|---|---|---|",
             f"| success (closer to the truth than any pseudo solution) | {p['success']}/{p['trials']} | {s['success']}/{r['trials']} | "
             f"{g['success']}/{r['trials']} |",
             f"| all three positions within {r['config']['success_tol']:g} m | -- | {s['within_tol']} | {g['within_tol']} |"]
    for cam in ("C2", "C3", "C"):
        lines.append(f"| {cam} mean (std), own successes | {p[cam][0]:.1e} ({p[cam][1]:.1e}) | {_f(s[cam]['mean'])} ({_f(s[cam]['std'])}) | "
                     f"{_f(g[cam]['mean'])} ({_f(g[cam]['std'])}) |")
    sc, gc = s["common_trials"], g["common_trials"]
    for cam in ("C2", "C3", "C"):
        lines.append(f"| {cam} mean (std), the {r['common_successes']} trials both got right | -- | "
                     f"{_f(sc[cam]['mean'])} ({_f(sc[cam]['std'])}) | {_f(gc[cam]['mean'])} ({_f(gc[cam]['std'])}) |")
    e = r["evidence"]
    lines += ["", f"C1 is the reference (error 0). Seed: C2, C3 from the three-robot algorithm (graphloc.vision.mutual) on the "
                  f"noisy omni pixels, then P3P + straight-line test (no threshold: the seed's 0.003 m would only reject more). "
                  f"graphloc: one GTSAM graph over all six cameras (mutual and climber bearings, known |T_12|, the climbing "
                  f"robot's rotation held over its straight move), started from the same front-end. Why the paper's accuracy is not reached: with "
                  f"the *true* ground positions the genuine P3P candidate alone is already {e['genuine_p3p_error_true_ground_median_m']:.3f} m "
                  f"off (median; p90 {e['genuine_p3p_error_true_ground_p90_m']:.3f} m) at 0.5 px on a 640 px / 120 deg camera, "
                  f"i.e. {e['genuine_p3p_error_true_ground_median_m'] / r['config']['scale']:.1e} relative -- the paper's 5.7e-4 "
                  f"is below this noise floor. The seed's straight-line test is weak here: median line error of the chosen "
                  f"combination {s['line_error_median_m']:.3f} m vs {s['second_line_error_median_m']:.3f} m for the runner-up. "
                  f"graphloc's failures: {gf['ground_triangle_rejected']} ground triangles rejected by graphloc.vision.mutual "
                  f"(e.g. noise pushed a pixel past the omni field of view), {gf['consistent_fit_ill_conditioned']} fits as "
                  f"consistent as the successes' (graph error <= their 99th percentile {gf['success_graph_error_p99']:.1f}: "
                  f"ill-conditioned, the P3P singularity the seed blames for its 3 failures), {gf['poor_fit_wrong_basin']} "
                  f"poor fits, {gf['optimizer_failed']} optimizer failures. Simulation: {fl['camera_trials_redrawn']} camera placements and "
                  f"{fl['formations_redrawn_not_mutually_visible']} ground formations (a robot outside another's 120 deg omni "
                  f"field of view) redrawn, {fl['ground_orientation_redraws']} ground orientations redrawn."]
    return "\n".join(lines) + "\n"


def markdown_table_ii(r: dict) -> str:
    d = r["deterministic_ms"]
    lines = ["### Seed 000 Table II: running time (this machine, median per trial / mean per update)", "",
             "| algorithm | paper | seed baseline (ours) | graphloc |", "|---|---|---|---|",
             f"| deterministic (3 x P3P + straight-line test; graphloc + joint GTSAM) | {r['paper_ms']['deterministic']} ms | "
             f"{d['seed_baseline']:.2f} ms | {d['graphloc']:.2f} ms |"]
    if "deterministic_batched_ms" in r:
        b = r["deterministic_batched_ms"]
        lines.append(f"| the same, all Table I trials batched (per trial; graphloc across workers) | -- | "
                     f"{b['seed_baseline']:.3f} ms | {b['graphloc']:.2f} ms |")
    if "update_ms" in r:
        u = r["update_ms"]
        lines.append(f"| one update (belief vector Def. 1 / HypothesisTracker) | {r['paper_ms']['update']} ms | "
                     f"{u['belief_def1']:.3f} ms | {u['tracker']:.3f} ms |")
        lines += ["", f"Particle filter (seed 004) {u['particle_filter']:.3f} ms, belief Def. 2 {u['belief_def2']:.3f} ms per update."]
    c = r["bearing_custom_factor_linearize"]
    lines += ["", "The paper's times are Matlab on a 2011 PC, including the simulation; ours exclude it. graphloc's "
                  f"joint graph uses the Python CustomFactor bearing_factor (Pose3 -> Pose3, no built-in fits): "
                  f"{1e6 * c['custom_s']:.0f} us per linearization vs {1e6 * c['builtin_s']:.0f} us for the built-in "
                  f"BearingFactor3D ({c['ratio']:.1f}x)."]
    return "\n".join(lines) + "\n"


def markdown_table_iii(r: dict) -> str:
    lines = [f"### Seed 000 Table III: mean updates to converge ({r['config']['runs']} runs per cell; wrong first locks / never converged)", "",
             "| cell | paper | seed baseline (ours): belief Def. 1 | belief Def. 2 | particle filter (seed 004) | graphloc HypothesisTracker | graphloc fewer than paper and belief |",
             "|---|---|---|---|---|---|---|"]
    for name, c in r["cells"].items():
        def cell(m):
            x = c[m]
            return f"{_f(x['mean_updates_to_converge'], '.2f')} ({x['wrong_locks']}/{x['never_converged']})"
        lines.append(f"| {name} | {c['paper_table_iii']} | {cell('belief_def1')} | {cell('belief_def2')} | "
                     f"{cell('particle_filter')} | {cell('tracker')} | {'yes' if r['graphloc_fewer_updates_than_paper_and_belief'][name] else 'no'} |")
    lines += ["", "Mean updates to the first *correct* lock (runs never correctly locked):", "",
              "| cell | paper | belief Def. 1 | belief Def. 2 | particle filter | graphloc HypothesisTracker | graphloc fewer than paper and belief |",
              "|---|---|---|---|---|---|---|"]
    for name, c in r["cells"].items():
        def correct(m):
            x = c[m]
            return f"{_f(x['mean_updates_to_correct_lock'], '.2f')} ({x['never_correct']})"
        lines.append(f"| {name} | {c['paper_table_iii']} | {correct('belief_def1')} | {correct('belief_def2')} | "
                     f"{correct('particle_filter')} | {correct('tracker')} | "
                     f"{'yes' if r['graphloc_fewer_updates_to_correct_lock_than_paper_and_belief'][name] else 'no'} |")
    lines += ["", "Runs, engines and convergence rule: graphloc.experiments.hypotheses (update 1 = first odometry step). "
                  "Wrong first locks count commits on a non-genuine candidate: a method that converges fast but wrongly is not better."]
    return "\n".join(lines) + "\n"


def markdown_seed004(r: dict) -> str:
    lines = [f"### Seed 004 Table 1: P3P position error [m] ({r['runs']} tracks x {r['frames']} frames per cell)", "",
             "| focal | noise var [px^2] | paper mean (std) | seed baseline raw P3P: RMS / mean (std) | graphloc smoothed: RMS / mean (std) |",
             "|---|---|---|---|---|"]
    for c in r["cells"]:
        p, s, g = c["paper"], c["seed_baseline_raw_p3p"], c["graphloc_smoothed"]
        lines.append(f"| {c['focal_mm']:g} mm | {c['noise_variance']:g} | {p['mean']:.4f} ({p['std']:.4f}) | "
                     f"{s['rms']:.4f} / {s['mean']:.4f} ({s['std']:.4f}) | {g['rms']:.4f} / {g['mean']:.4f} ({g['std']:.4f}) |")
    st = r["setup"]
    lines += ["", f"Setup where the seed is silent: camera {st['height']} m above the LEDs, pixel pitch {st['pixel_pitch_um']} um "
                  f"({st['width']}x{st['height_px']}), track step {st['step']} m, odometry {100 * st['odometry_noise']:.0f} % / "
                  f"{st['odometry_rot_sigma']} rad. The absolute errors depend on these (not given in the seed), so the paper's "
                  "numbers are not matched; both columns use the genuine P3P candidate of the same frames. A narrow lens looking "
                  "down on a 0.3 m triangle from this range sees it nearly fronto-parallel, where its tilt is observable only at "
                  "second order (cos t ~ 1 - t^2/2), so the tilt -- and with it the camera's lateral position -- is "
                  "ill-conditioned; the raw error stays large away from the danger cylinder too "
                  f"({r['cells'][0]['raw_p3p_rms_far_from_danger_cylinder']:.3f} m RMS vs {r['cells'][0]['raw_p3p_rms_near_danger_cylinder']:.3f} m "
                  "near it in the first cell). Graph-smoothed RMS below raw P3P in all nine cells: "
                  f"{'yes' if r['target_smoothed_below_raw_in_all_cells'] else 'NO'}."]
    return "\n".join(lines) + "\n"
