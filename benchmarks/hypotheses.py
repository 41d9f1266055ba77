"""Seed 000 (000_05137a0a9c449be3.txt) Sec. VI-B, Table III trials: HypothesisTracker vs the
seeds' baselines on the probabilistic setup, one run per (ceiling, curve, index), simulated once
and fed to every method (same CandidateSets, same odometry): belief vector Def. 1 and Def. 2
(seed 000 Sec. V-B), particle filter (seed 004 Sec. II-C), HypothesisTracker, and on the
straight curve the straight-line test (seed 000 Sec. IV). Per method and cell (`summarize`):
mean updates to converge = updates until the FIRST commit, right or wrong (update 1 = first
odometry step, after the 0.3 s first interval); wrong locks (first commit on a non-genuine
candidate, or > WRONG_DISTANCE from the truth when the committed track has no candidate); mean
updates to the first CORRECT commit (the comparison that counts: a fast wrong lock is not
convergence); runs that never converge; relocalizations; position RMSE over the committed
frames, and for the tracker its committed modes re-solved by batch LM and by frame-by-frame
iSAM2 (`resolve_decided`). "front_door" is graphloc itself on the same run: its
`graphloc simulate` log through `open_run` and the team graph
(`benchmarks.front_door.feng_table_iii_run`), the column of seed 000 Table III.
Used by `scripts/reproduce.py seed000-table3`
(benchmarks.seed000) and scripts/bench_hypotheses.py
(benchmarks.bench_hypotheses).
"""

from __future__ import annotations

import time

import gtsam
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from benchmarks.baselines.belief_vector import BeliefVector, BeliefVectorConfig
from benchmarks.baselines.particle_filter import ParticleFilter, ParticleFilterConfig
from benchmarks.baselines.straight_line import StraightLineBaseline, StraightLineConfig
from graphloc.datasets.feng import (
    CEILINGS,
    FengProbabilisticConfig,
    FengProbabilisticScenario,
    ceiling_plane,
    noisy_odometry,
    odometry_covariance,
)
from benchmarks.front_door import feng_table_iii_run
from benchmarks.locks import lock_statistics
from graphloc.hypotheses import HypothesisTracker, TrackerConfig
from graphloc.keys import decode, pose_key
from benchmarks.track_smoothing import decided, track_graph
from graphloc.seams import Odometry
from graphloc.session import Session, SessionConfig

CELLS = [(ceiling, curve) for curve in ("line", "sine", "quadratic") for ceiling in CEILINGS]
PAPER_TABLE_III = {
    ("level", "line"): 6.93,
    ("sloped", "line"): 7.31,
    ("level", "sine"): 11.22,
    ("sloped", "sine"): 19.47,
    ("level", "quadratic"): 8.97,
    ("sloped", "quadratic"): 14.15,
}
METHODS = (
    "belief_def1",
    "belief_def2",
    "particle_filter",
    "straight_line",
    "tracker",
    "front_door",
)
WRONG_DISTANCE = 0.25  # [m] committed pose this far from the truth without a candidate = wrong


@config_dataclass
class TableIIIConfig:
    """The trials' options (seed 000 Sec. VI-B): `runs` runs per (ceiling, curve) cell (paper:
    100) over `workers` processes; tracker K (max_hypotheses), belief Def. 2 lambda (lam),
    straight-line snapshot spacing / commit threshold [m], pixel noise [px], seed offset; the
    readings of the seed's setup (benchmarks.seed_baselines): the belief vector's
    Def. 1 / Def. 2 likelihood mappings (benchmarks.baselines.belief_vector.LIKELIHOODS) and the
    odometry noise model (graphloc.datasets.feng.ODOMETRY_MODELS), and the belief vector's
    action frame (benchmarks.baselines.belief_vector.ACTION_FRAMES; "world": the belief engines
    get world-frame motion readings, `world_odometry_steps`)."""

    runs: int = setting(100, ge=1)
    workers: int = setting(2, ge=1)
    max_hypotheses: int = 8
    lam: float = 5.0
    line_spacing: int = 10
    line_max_error: float = 0.05
    pixel_sigma: float = 0.5
    seed_offset: int = 0
    def1_likelihood: str = "inner_product"
    def2_likelihood: str = "distance_angle"
    odometry_model: str = "per_axis"
    action_frame: str = "solution"


def make_engine(method: str, ceiling: str, args: TableIIIConfig, seed: int):
    if method == "belief_def1":
        return BeliefVector(
            BeliefVectorConfig(likelihood=args.def1_likelihood, action_frame=args.action_frame)
        )
    if method == "belief_def2":
        return BeliefVector(
            BeliefVectorConfig(
                likelihood=args.def2_likelihood, lam=args.lam, action_frame=args.action_frame
            )
        )
    if method == "particle_filter":
        # the motion plane is the ceiling (seed 004 Algorithm 1 line 7)
        return ParticleFilter(
            ParticleFilterConfig(plane_normal=tuple(ceiling_plane(ceiling).normal), seed=seed)
        )
    if method == "straight_line":
        return StraightLineBaseline(
            StraightLineConfig(spacing=args.line_spacing, max_error=args.line_max_error)
        )
    if method == "tracker":
        return HypothesisTracker(TrackerConfig(max_hypotheses=args.max_hypotheses))
    raise ValueError(f"unknown method {method!r}")


def odometry_steps(run, sim: FengProbabilisticConfig) -> list:
    return [None] + [
        Odometry(
            o,
            odometry_covariance(
                o, sim.odometry_noise, sim.odometry_rot_sigma, model=sim.odometry_model
            ),
        )
        for o in run.odometry
    ]


def world_odometry_steps(run, sim: FengProbabilisticConfig) -> list:
    """The belief vector's world-frame motion readings (action_frame "world") of one run, seeded
    from the run's seed."""
    rng = np.random.default_rng([sim.seed, 7])
    # a_t read as a world-frame motion sensor: the true displacements with noisy_odometry's
    # translation noise, as identity-rotation steps
    moves = np.diff(run.t_wc, axis=0)
    eye = np.broadcast_to(np.eye(3), (len(moves), 3, 3))
    steps = noisy_odometry(eye, moves, sim.odometry_noise, 0.0, rng, sim.odometry_model)
    return [None] + [Odometry(o, np.eye(6)) for o in steps]


def evaluate(engine, run, odometry, smooth: bool = False) -> dict:
    """Feed one run through one engine. A locked frame is correct when the committed candidate
    is the genuine one (meta["genuine"], nearest the truth) or the committed pose is within
    WRONG_DISTANCE of the truth (near the P3P fold two candidates are close; a coasting track
    has no candidate). smooth: also re-solve the run with the committed modes fixed in a batch
    Session (Levenberg-Marquardt over all poses) and report its RMSE on the same frames."""
    latency, decisions, frames = [], [], []
    for k, (cands, odo) in enumerate(zip(run.candidates, odometry)):
        t0 = time.perf_counter()
        d = engine.update(cands, odo)
        latency.append(time.perf_counter() - t0)
        decisions.append(d)
        if not d.locked:
            frames.append((k, False, False, 0.0, d.relocalized))
            continue
        err2 = float(np.sum((d.pose.translation() - run.t_wc[k]) ** 2))
        ok = (
            d.committed >= 0 and d.committed == cands.meta.get("genuine", -1)
        ) or err2 < WRONG_DISTANCE**2
        frames.append((k, True, ok, err2, d.relocalized))
    rmse_batch = rmse_online = None
    resolved_frames = 0
    if smooth and any(d.locked and d.committed >= 0 for d in decisions):
        batch, online = resolve_decided(run, odometry, decisions)
        resolved = sorted(online)
        resolved_frames = len(resolved)
        rmse_batch = _rmse([batch[k].translation() - run.t_wc[k] for k in resolved])
        rmse_online = _rmse([online[k].translation() - run.t_wc[k] for k in resolved])
    return {
        **lock_statistics(frames),
        "rmse_locked_batch": rmse_batch,
        "rmse_locked_online": rmse_online,
        "resolved_frames": resolved_frames,
        "frames": len(run),
        "mean_latency_ms": 1e3 * float(np.mean(latency)),
    }


def resolve_decided(run, odometry, decisions) -> tuple[dict, dict]:
    """The tracker's committed modes re-solved as one factor graph (`track_graph`)
    two ways through `graphloc.session.Session`: batch (LM over all poses, smoothed) and online
    (iSAM2, the graph added frame by frame from the first committed frame: every factor whose
    newest pose is frame k in step k; the estimate of frame k read right after step k, i.e.
    causal like the tracker). Returns ({frame: Pose3} batch, {frame: Pose3} online) over the
    locked frames from the first commit on."""
    chosen, initial = decided(decisions)
    graph, values = track_graph(run.candidates, odometry, chosen, initial)
    first = next(k for k, d in enumerate(decisions) if d.locked and d.committed >= 0)
    frames = [k for k, d in enumerate(decisions) if d.locked and k >= first]
    batch_session = Session(SessionConfig(mode="batch"))
    batch_session.add(graph, values)
    est = batch_session.estimate()
    batch = {k: est.atPose3(pose_key(0, k)) for k in frames}
    by_frame: dict[int, list] = {}
    for i in range(graph.size()):
        factor = graph.at(i)
        ts = [decode(key)[2] for key in factor.keys()]
        if min(ts) >= first:  # before the first commit the chain has no absolute anchor
            by_frame.setdefault(max(ts), []).append(factor)
    online_session, online, wanted = Session(SessionConfig(mode="online")), {}, set(frames)
    for k in range(first, len(decisions)):
        init = gtsam.Values()
        init.insert(pose_key(0, k), values.atPose3(pose_key(0, k)))
        online_session.add(by_frame.get(k, []), init, time=float(run.times[k]))
        if k in wanted:
            online[k] = online_session.estimate([pose_key(0, k)]).atPose3(pose_key(0, k))
    return batch, online


def _rmse(errors) -> float:
    return float(np.sqrt(np.mean(np.sum(np.square(errors), axis=1))))


def trial(job) -> dict:
    ceiling, curve, run_index, args = job
    seed = args.seed_offset + 1000 * CELLS.index((ceiling, curve)) + run_index
    sim = FengProbabilisticConfig(
        ceiling=ceiling,
        curve=curve,
        seed=seed,
        pixel_sigma=args.pixel_sigma,
        odometry_model=args.odometry_model,
    )
    run = FengProbabilisticScenario.simulate(sim)
    odometry = odometry_steps(run, sim)
    out = {
        "ceiling": ceiling,
        "curve": curve,
        "run": run_index,
        "seed": seed,
        "genuine_error_median": float(
            np.median([c.meta.get("genuine_error", np.nan) for c in run.candidates])
        ),
    }
    world = world_odometry_steps(run, sim) if args.action_frame == "world" else None
    overrides = {
        "ceiling": ceiling,
        "curve": curve,
        "pixel_sigma": args.pixel_sigma,
        "odometry_model": args.odometry_model,
    }
    out["front_door"] = feng_table_iii_run(overrides, seed, WRONG_DISTANCE)
    for method in METHODS:
        if method == "front_door" or (method == "straight_line" and curve != "line"):
            continue
        steps = world if world is not None and method.startswith("belief") else odometry
        out[method] = evaluate(
            make_engine(method, ceiling, args, seed), run, steps, smooth=method == "tracker"
        )
    return out


def summarize(trials: list[dict]) -> dict:
    """Per cell and method statistics of `trial` results, in run order whatever order the
    worker processes returned them in (so that pooled sums are bit-reproducible)."""
    table = {}
    for ceiling, curve in CELLS:
        rows = sorted(
            (t for t in trials if t["ceiling"] == ceiling and t["curve"] == curve),
            key=lambda t: t["run"],
        )
        cell = {
            "runs": len(rows),
            "paper_table_iii": PAPER_TABLE_III[(ceiling, curve)],
            "p3p_genuine_error_median_m": float(
                np.median([r["genuine_error_median"] for r in rows])
            ),
        }
        for method in METHODS:
            res = [r[method] for r in rows if method in r]
            if not res:
                continue
            conv = [r["converged"] for r in res if r["converged"] is not None]
            correct = [r["correct_lock"] for r in res if r["correct_lock"] is not None]
            med = [r["median_error_locked"] for r in res if r["median_error_locked"] is not None]
            locked = sum(r["locked_frames"] for r in res)
            cell[method] = {
                "mean_updates_to_converge": float(np.mean(conv)) if conv else None,
                "never_converged": sum(r["converged"] is None for r in res),
                "wrong_locks": sum(r["wrong"] for r in res),
                "mean_updates_to_correct_lock": float(np.mean(correct)) if correct else None,
                "never_correct": sum(r["correct_lock"] is None for r in res),
                # a run never correctly committed counts with its whole length (a lower bound)
                "mean_updates_to_correct_lock_censored": float(
                    np.mean(
                        [
                            r["frames"] - 1 if r["correct_lock"] is None else r["correct_lock"]
                            for r in res
                        ]
                    )
                ),
                "wrong_locked_frame_fraction": sum(r["wrong_locked_frames"] for r in res) / locked
                if locked
                else None,
                "relocalizations": sum(r["relocalizations"] for r in res),
                "rmse_locked_frames_m": _pooled_rmse(
                    [(r["rmse_locked"], r["locked_frames"]) for r in res]
                ),
                "median_error_locked_frames_m": float(np.median(med)) if med else None,
                "rmse_locked_frames_batch_m": _pooled_rmse(
                    [(r["rmse_locked_batch"], r["resolved_frames"]) for r in res]
                ),
                "rmse_locked_frames_online_m": _pooled_rmse(
                    [(r["rmse_locked_online"], r["resolved_frames"]) for r in res]
                ),
                "mean_latency_ms": float(np.mean([r["mean_latency_ms"] for r in res])),
            }
        table[f"{ceiling}/{curve}"] = cell
    return table


def _pooled_rmse(pairs) -> float | None:
    """RMSE pooled over runs from (per-run RMSE, frames) pairs (None entries skipped)."""
    pairs = [(r, n) for r, n in pairs if r is not None and n]
    return (
        float(np.sqrt(sum(r * r * n for r, n in pairs) / sum(n for _, n in pairs)))
        if pairs
        else None
    )
