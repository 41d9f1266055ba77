"""Planar multi-robot smoothing: PlanarRun -> per-frame factors -> Session (batch LM or online
iSAM2) -> trajectories. The function behind `graphloc smooth` and `graphloc online`.

Frames are a common clock grid t_k = start + k*dt shared by all robots (key pose_key(r, k)).
Per frame: one odometry between-factor per robot (velocity odometry integrated to the grid,
covariance from the velocity noise model; a prior from the initial pose at k = 0), range-bearing
factors of the measurements snapped to the frame (each re-expressed in the observer's frame at
t_k using its own odometry, so only the observed robot's motion over <= dt/2 is neglected), and
priors on known landmarks (one prior-pinned anchor per observation, see ANCHOR_BASE; unknown
landmarks -- cooperative SLAM -- are shared variables initialized from their first observation).
Batch and online solve the SAME factor list; online adds it frame by frame and initializes new
poses from its own latest estimate.
"""

from __future__ import annotations

import json
import time as _time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.factors.odometry import VelocityNoise, between_factor, between_poses, compose_poses, integrate_unicycle
from graphloc.factors.range_bearing import landmark_factor_2d, robot_factor_2d
from graphloc.factors.robust import Kernel, KernelPolicy, downweighted
from graphloc.eval import ate_over_time, planar_to_evo, trajectory_metrics, write_tum
from graphloc.io import MANIFEST, PlanarRun, SkipReport, read_planar_run
from graphloc.keys import landmark_key, pose_key
from graphloc.plots import Series, plot_series, plot_trajectories
from graphloc.session import Session, SessionConfig

# Known landmarks observed k times become k "anchor" variables landmark_key(ANCHOR_BASE + j), each
# pinned by the landmark's prior: the same information as a unary factor, but no long-lived
# variable tying thousands of factors together (which makes every iSAM2 update O(n)).
ANCHOR_BASE = 100_000_000


@dataclass(frozen=True)
class SmoothingConfig:
    """keyframe_dt [s]; which measurements to use; measurement noise (bearing [rad], range
    sigma = hypot(range_sigma, range_sigma_per_m * range)); robust kernels by factor type (odometry,
    landmark, inter_robot); odometry noise;
    anchor_known_landmarks: known landmarks get one prior-pinned copy per observation (see ANCHOR_BASE);
    initial-pose prior sigmas (x, y, theta); landmark prior sigma floor [m]; kernel-weight
    threshold below which a factor counts as down-weighted; iSAM2 settings for online mode."""

    keyframe_dt: float = 0.25
    anchor_known_landmarks: bool = True
    use_landmarks: bool = True
    use_inter_robot: bool = True
    landmark_priors: bool = True
    bearing_sigma: float = 0.02
    range_sigma: float = 0.05
    range_sigma_per_m: float = 0.035
    kernels: KernelPolicy = KernelPolicy({"landmark": Kernel("cauchy", 2.0), "inter_robot": Kernel("cauchy", 2.0)})
    velocity_noise: VelocityNoise = VelocityNoise(density_v=0.01, density_w=0.05)
    initial_sigma: tuple = (0.05, 0.05, 0.02)
    landmark_prior_floor: float = 0.01
    downweight_threshold: float = 0.1
    relinearize_threshold: float = 0.05
    relinearize_skip: int = 10
    wildfire_threshold: float = 0.01
    partial_relinearization_check: bool = True
    predict_every: int = 1
    lm_max_iterations: int = 100

    def __post_init__(self):
        positive = ("keyframe_dt", "bearing_sigma", "range_sigma", "landmark_prior_floor")
        for name in positive:
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"SmoothingConfig.{name} must be finite > 0, got {v}")
        if len(self.initial_sigma) != 3 or not all(np.isfinite(s) and s > 0 for s in self.initial_sigma):
            raise ValueError(f"SmoothingConfig.initial_sigma must be 3 positive numbers, got {self.initial_sigma}")
        if not (self.use_landmarks or self.use_inter_robot):
            raise ValueError("SmoothingConfig: using neither landmarks nor inter-robot measurements leaves only odometry")

    def session_config(self, mode: str) -> SessionConfig:
        return SessionConfig(mode=mode, lm_max_iterations=self.lm_max_iterations,
                             relinearize_threshold=self.relinearize_threshold, relinearize_skip=self.relinearize_skip,
                             wildfire_threshold=self.wildfire_threshold,
                             partial_relinearization_check=self.partial_relinearization_check)


@dataclass(frozen=True)
class Frame:
    """Everything added at frame k: factors (GTSAM graph), the robots' odometry deltas from k-1,
    new landmark keys with their prior positions (NaN if unknown) and first observation."""

    k: int
    time: float
    graph: gtsam.NonlinearFactorGraph
    deltas: np.ndarray  # (R,3), NaN row at k = 0
    new_landmarks: tuple  # of (key, landmark id, prior xy or None, observer index, bearing, range)


@dataclass(frozen=True)
class Problem:
    """frame_times (K,); dead_reckoning (R,K,3); frames (K); factor index ranges by type; counts."""

    run: PlanarRun
    config: SmoothingConfig
    frame_times: np.ndarray
    dead_reckoning: np.ndarray
    frames: tuple
    factor_types: np.ndarray  # (n_factors,) str label of every factor in frame order
    counts: dict
    skips: SkipReport


@dataclass(frozen=True)
class SmoothingResult:
    """estimate (R,K,3) final smoothed poses; causal (R,K,3) online estimate of each frame right after
    its own update (NaN in batch); latencies (K,) per-frame update seconds; wall_s total solve time."""

    mode: str
    robots: tuple
    frame_times: np.ndarray
    estimate: np.ndarray
    causal: np.ndarray
    dead_reckoning: np.ndarray
    latencies: np.ndarray
    wall_s: float
    downweighted: dict
    counts: dict
    skips: SkipReport
    landmarks: dict = field(default_factory=dict)  # landmark id -> estimated xy (SLAM mode)

    @property
    def realtime_factor(self) -> float:
        """Run duration divided by solve wall time (> 1: faster than real time)."""
        return float((self.frame_times[-1] - self.frame_times[0]) / max(self.wall_s, 1e-12))


def build_problem(run: PlanarRun, config: SmoothingConfig = SmoothingConfig(), progress: bool = False) -> Problem:
    """Integrate odometry to the frame grid and turn every usable measurement into a factor."""
    skips = SkipReport()
    skips.merge(run.skips)
    R = len(run.robots)
    if not np.isfinite(run.initial_poses).all():
        missing = [run.robots[i] for i in np.flatnonzero(~np.isfinite(run.initial_poses).all(axis=1))]
        raise ValueError(f"{run.name}: initial pose unknown for robots {missing} (manifest field 'initial_pose' "
                         f"or ground truth needed to anchor the frame)")
    dt = config.keyframe_dt
    K = int(np.floor(run.duration() / dt + 1e-9)) + 1
    if K < 2:
        raise ValueError(f"{run.name}: run of {run.duration():.3f} s is shorter than one keyframe step ({dt} s)")
    times = run.start_time + dt * np.arange(K)

    deltas = np.full((R, K, 3), np.nan)
    covs = np.zeros((R, K, 3, 3))
    dead = np.zeros((R, K, 3))
    for r in range(R):
        od = run.odometry[r]
        integ = integrate_unicycle(od[:, 0], od[:, 1], od[:, 2], times, config.velocity_noise, run.initial_poses[r])
        dead[r], deltas[r, 1:], covs[r, 1:] = integ.poses, integ.deltas, integ.covariances

    # --- measurements: select, snap to frames, re-express in the observer's frame at t_k ---
    t, obs_r, tgt, lm = run.obs_time, run.obs_robot, run.obs_target_robot, run.obs_landmark
    counts = {"landmark_measurements": int((lm >= 0).sum()), "inter_robot_measurements": int((tgt >= 0).sum())}
    use = ((lm >= 0) & config.use_landmarks) | ((tgt >= 0) & config.use_inter_robot)
    counts["excluded_by_option"] = int((~use).sum())
    outside = use & ((t < times[0] - dt / 2) | (t > times[-1] + dt / 2))
    if outside.any():
        skips.add("outside_run", f"{run.name}: {int(outside.sum())} measurements outside the odometry span", int(outside.sum()))
    use &= ~outside
    sel = np.flatnonzero(use)
    frame_of = np.clip(np.rint((t[sel] - times[0]) / dt).astype(int), 0, K - 1)
    bearing = np.empty(sel.size)
    rng = np.empty(sel.size)
    for r in range(R):
        mine = obs_r[sel] == r
        if not mine.any():
            continue
        od = run.odometry[r]
        stamps = np.union1d(times, t[sel][mine])
        pose_at = integrate_unicycle(od[:, 0], od[:, 1], od[:, 2], stamps, config.velocity_noise,
                                     run.initial_poses[r]).poses
        at_meas = pose_at[np.searchsorted(stamps, t[sel][mine])]
        at_frame = pose_at[np.searchsorted(stamps, times[frame_of[mine]])]
        # pose at measurement time in the frame-time body frame, then the measured point through it
        rel = between_poses(at_frame, at_meas)
        b0, r0 = run.obs_bearing[sel][mine], run.obs_range[sel][mine]
        pt = compose_poses(rel, np.stack([r0 * np.cos(b0), r0 * np.sin(b0), np.zeros_like(b0)], axis=1))
        bearing[mine], rng[mine] = np.arctan2(pt[:, 1], pt[:, 0]), np.hypot(pt[:, 0], pt[:, 1])

    lm_prior = {int(i): (xy, np.maximum(s, config.landmark_prior_floor))
                for i, xy, s in zip(run.landmark_ids, run.landmark_xy, run.landmark_sigma)} if config.landmark_priors else {}
    order = np.argsort(frame_of, kind="stable")
    bounds = np.searchsorted(frame_of[order], np.arange(K + 1))
    prior_noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(config.initial_sigma, dtype=float))
    seen: set[int] = set()
    n_anchors = 0
    frames, types = [], []
    for k in tqdm(range(K), desc="building factors", disable=not progress, unit="frame"):
        graph = gtsam.NonlinearFactorGraph()
        for r in range(R):
            if k == 0:
                graph.add(gtsam.PriorFactorPose2(pose_key(r, 0), gtsam.Pose2(*run.initial_poses[r]), prior_noise))
                types.append("prior")
            else:
                graph.add(between_factor(pose_key(r, k - 1), pose_key(r, k), gtsam.Pose2(*deltas[r, k]), covs[r, k],
                                         config.kernels.kernel("odometry")))
                types.append("odometry")
        new_landmarks = []
        for j in order[bounds[k]:bounds[k + 1]]:
            i = sel[j]
            sig = (config.bearing_sigma, float(np.hypot(config.range_sigma, config.range_sigma_per_m * rng[j])))
            observer = pose_key(obs_r[i], k)
            if tgt[i] >= 0:
                graph.add(robot_factor_2d(observer, pose_key(tgt[i], k), bearing[j], rng[j], sig,
                                          config.kernels.kernel("inter_robot")))
                types.append("inter_robot")
                continue
            lid = int(lm[i])
            prior = lm_prior.get(lid)
            if prior is not None and config.anchor_known_landmarks:
                # known landmark: a fresh copy of it per observation, pinned by the prior
                key = landmark_key(ANCHOR_BASE + n_anchors)
                n_anchors += 1
                new_landmarks.append((key, lid, prior[0], int(obs_r[i]), bearing[j], rng[j]))
            else:
                key = landmark_key(lid)
                if lid not in seen:
                    new_landmarks.append((key, lid, None if prior is None else prior[0], int(obs_r[i]), bearing[j], rng[j]))
            if prior is not None and (key != landmark_key(lid) or lid not in seen):
                graph.add(gtsam.PriorFactorPoint2(key, prior[0], gtsam.noiseModel.Diagonal.Sigmas(prior[1])))
                types.append("landmark_prior")
            seen.add(lid)
            graph.add(landmark_factor_2d(observer, key, bearing[j], rng[j], sig, config.kernels.kernel("landmark")))
            types.append("landmark")
        frames.append(Frame(k, float(times[k]), graph, deltas[:, k], tuple(new_landmarks)))
    types_arr = np.array(types)
    counts.update({"frames": K, "robots": R, "landmarks_seen": len(seen), "landmark_anchors": n_anchors,
                   **{f"factors_{name}": int((types_arr == name).sum()) for name in np.unique(types_arr)}})
    return Problem(run, config, times, dead, tuple(frames), types_arr, counts, skips)


def _landmark_guess(pose: np.ndarray, bearing: float, rng: float) -> np.ndarray:
    a = pose[2] + bearing
    return np.array([pose[0] + rng * np.cos(a), pose[1] + rng * np.sin(a)])


def solve(problem: Problem, mode: str = "batch", progress: bool = False) -> SmoothingResult:
    """Add every frame to a Session (batch: initial guess = dead reckoning, one LM at the end;
    online: iSAM2 update per frame, new poses predicted from the latest estimate)."""
    cfg = problem.config
    R, K = problem.dead_reckoning.shape[:2]
    session = Session(cfg.session_config(mode))
    causal = np.full((R, K, 3), np.nan)
    latest = problem.dead_reckoning[:, 0].copy()
    start = _time.perf_counter()
    for frame in tqdm(problem.frames, desc=f"{mode} frames", disable=not progress, unit="frame"):
        k = frame.k
        if mode == "online" and k > 0:
            guess = compose_poses(latest, frame.deltas)
            latest = guess
        else:
            guess = problem.dead_reckoning[:, k]
        values = gtsam.Values()
        for r in range(R):
            values.insert(pose_key(r, k), gtsam.Pose2(*guess[r]))
        for key, _lid, prior_xy, observer, b, rg in frame.new_landmarks:
            xy = prior_xy if prior_xy is not None else _landmark_guess(guess[observer], b, rg)
            values.insert(key, np.asarray(xy, dtype=float))
        session.add(frame.graph, values, time=frame.time)
        if mode == "online" and (k % cfg.predict_every == 0 or k == K - 1):
            est = session.estimate([pose_key(r, k) for r in range(R)])
            latest = np.array([_pose_array(est.atPose2(pose_key(r, k))) for r in range(R)])
            causal[:, k] = latest
    final = session.estimate()
    wall = _time.perf_counter() - start
    estimate = np.array([[_pose_array(final.atPose2(pose_key(r, k))) for k in range(K)] for r in range(R)])
    landmarks = {lid: np.asarray(final.atPoint2(key)) for f in problem.frames
                 for key, lid, *_ in f.new_landmarks if key == landmark_key(lid)}
    down = {}
    for ftype in ("odometry", "landmark", "inter_robot"):
        if cfg.kernels.kernel(ftype).name == "none":
            continue
        idx = np.flatnonzero(problem.factor_types == ftype)
        rep = downweighted(session.graph, final, cfg.downweight_threshold, indices=idx)
        down[ftype] = {"robust_factors": rep.n_robust, "downweighted": rep.n_downweighted,
                       "threshold": cfg.downweight_threshold}
    latencies = session.latencies()
    return SmoothingResult(mode, problem.run.robots, problem.frame_times, estimate, causal, problem.dead_reckoning,
                           latencies, wall, down, dict(problem.counts), problem.skips, landmarks)


def _pose_array(p: gtsam.Pose2) -> np.ndarray:
    return np.array([p.x(), p.y(), p.theta()])


def smooth_run(run: PlanarRun, config: SmoothingConfig = SmoothingConfig(), mode: str = "batch",
               progress: bool = True) -> SmoothingResult:
    """build_problem + solve: the one call behind `graphloc smooth` / `graphloc online`."""
    return solve(build_problem(run, config, progress=progress), mode=mode, progress=progress)


# ---- loading, evaluation and outputs (what the `smooth` / `online` verbs call) ------------------
def load_planar_run(path: str | Path, duration: float | None = None) -> PlanarRun:
    """A graphloc log directory (manifest.json) or an MRCLAM dataset directory -> PlanarRun,
    optionally truncated to the first `duration` seconds."""
    path = Path(path)
    if (path / MANIFEST).is_file():
        run = read_planar_run(path)
        return run if duration is None else truncate_run(run, duration)
    from graphloc.datasets.mrclam import MRCLAM, is_mrclam_dir

    if is_mrclam_dir(path):
        return MRCLAM(path, duration=duration).load()
    raise FileNotFoundError(f"{path}: neither a graphloc log (no {MANIFEST}) nor an MRCLAM directory (no Barcodes.dat)")


def truncate_run(run: PlanarRun, duration: float) -> PlanarRun:
    """The first `duration` seconds of `run` (after its start time)."""
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be finite > 0, got {duration}")
    end = run.start_time + duration
    keep = run.obs_time <= end
    return replace(
        run, odometry=tuple(od[od[:, 0] <= end] for od in run.odometry),
        groundtruth=tuple(None if g is None else g[g[:, 0] <= end] for g in run.groundtruth),
        obs_time=run.obs_time[keep], obs_robot=run.obs_robot[keep], obs_target_robot=run.obs_target_robot[keep],
        obs_landmark=run.obs_landmark[keep], obs_range=run.obs_range[keep], obs_bearing=run.obs_bearing[keep])


def evaluate(result: SmoothingResult, run: PlanarRun) -> dict:
    """Per-robot ATE/RPE (evo, SE(2)-aligned) of dead reckoning, the smoothed estimate and (online)
    the causal estimate; improvement ratios; latency and real-time statistics; skips; down-weighting."""
    per_robot = {}
    for r, name in enumerate(run.robots):
        gt = run.groundtruth[r]
        if gt is None or len(gt) < 3:
            per_robot[name] = {"groundtruth": False}
            continue
        ref = planar_to_evo(gt[:, 0], gt[:, 1:4])
        entry = {"groundtruth": True}
        tracks = {"dead_reckoning": result.dead_reckoning[r], result.mode: result.estimate[r]}
        if result.mode == "online":
            tracks["online_causal"] = result.causal[r]
        for label, poses in tracks.items():
            ok = np.isfinite(poses).all(axis=1)
            entry[label] = trajectory_metrics(ref, planar_to_evo(result.frame_times[ok], poses[ok])).as_dict()
        entry["ate_ratio_dead_reckoning_over_" + result.mode] = (
            entry["dead_reckoning"]["ate_rmse"] / max(entry[result.mode]["ate_rmse"], 1e-12))
        per_robot[name] = entry
    lat = result.latencies
    # per-frame latency exists only online (iSAM2 update per frame); batch solves once (solve_wall_s)
    latency = ({"mean": float(lat.mean() * 1e3), "p50": float(np.percentile(lat, 50) * 1e3),
                "p95": float(np.percentile(lat, 95) * 1e3), "max": float(lat.max() * 1e3)}
               if result.mode == "online" else None)
    return {
        "run": run.name, "mode": result.mode, "robots": list(run.robots),
        "duration_s": float(result.frame_times[-1] - result.frame_times[0]),
        "frames": int(len(result.frame_times)), "solve_wall_s": result.wall_s,
        "realtime_factor": result.realtime_factor,
        "latency_ms": latency,
        "per_robot": per_robot, "downweighted": result.downweighted, "counts": result.counts,
        "skipped": result.skips.as_dict(),
    }


def write_outputs(result: SmoothingResult, run: PlanarRun, metrics: dict, out_dir: str | Path) -> list[Path]:
    """TUM trajectories per robot (estimate and dead reckoning), metrics.json, and PNG plots
    (trajectories vs ground truth, ATE over time, per-frame latency)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for r, name in enumerate(run.robots):
        written.append(write_tum(out / f"{name}_{result.mode}.tum", result.frame_times, result.estimate[r]))
        written.append(write_tum(out / f"{name}_dead_reckoning.tum", result.frame_times, result.dead_reckoning[r]))
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    written.append(out / "metrics.json")
    colors = plt_colors(len(run.robots))
    est_series, ref_series, dr_series, err_series = [], [], [], []
    for r, name in enumerate(run.robots):
        est_series.append(Series(f"{name} {result.mode}", result.estimate[r][:, :2], color=colors[r]))
        dr_series.append(Series(f"{name} dead reckoning", result.dead_reckoning[r][:, :2], style=":", color=colors[r]))
        gt = run.groundtruth[r]
        if gt is not None and len(gt) >= 3:
            label = "ground truth" if not ref_series else "_nolegend_"  # one legend entry for all robots
            ref_series.append(Series(label, gt[:, 1:3], style="--", color="0.4"))
            ref = planar_to_evo(gt[:, 0], gt[:, 1:4])
            for label, poses, style in (("dead reckoning", result.dead_reckoning[r], ":"), (result.mode, result.estimate[r], "-")):
                t, e = ate_over_time(ref, planar_to_evo(result.frame_times, poses))
                err_series.append(Series(f"{name} {label}", t - run.start_time, e, style=style, color=colors[r]))
    written.append(plot_trajectories(out / "trajectories.png", est_series, ref_series, run.landmark_xy,
                                     title=f"{run.name}: {result.mode} vs ground truth"))
    written.append(plot_trajectories(out / "trajectories_dead_reckoning.png", dr_series + est_series, ref_series,
                                     run.landmark_xy, title=f"{run.name}: dead reckoning and {result.mode}"))
    if err_series:
        written.append(plot_series(out / "error_over_time.png", err_series, "time since start [s]",
                                   "position error after SE(2) alignment [m]", f"{run.name}: error over time", logy=True))
    if result.mode == "online":
        written.append(plot_series(out / "latency.png", [Series("update latency", result.frame_times - run.start_time,
                                                                 result.latencies * 1e3)],
                                   "time since start [s]", "latency per frame [ms]", f"{run.name}: online latency"))
    return written


def plt_colors(n: int) -> list:
    import matplotlib

    cmap = matplotlib.colormaps["tab10"]
    return [cmap(i % 10) for i in range(n)]


def run_and_report(run_path: str | Path, out_dir: str | Path, mode: str, config: SmoothingConfig = SmoothingConfig(),
                   duration: float | None = None, progress: bool = True) -> dict:
    """Load RUN, smooth it (batch or online), evaluate, write outputs; returns the metrics."""
    run = load_planar_run(run_path, duration)
    result = smooth_run(run, config, mode=mode, progress=progress)
    metrics = evaluate(result, run)
    metrics["config"] = _config_dict(config)
    write_outputs(result, run, metrics, out_dir)
    return metrics


def _config_dict(config: SmoothingConfig) -> dict:
    d = asdict(config)
    return json.loads(json.dumps(d, default=str))
