"""Online and batch at scale (issue 15), measured on one run through the path `graphloc smooth`
/ `online` take (`open_run` -> `team_graph` -> `solve`):

- batch: graphloc's solve (`Session`'s LM loop, iteration by iteration, plus the Python
  bookkeeping of the steps) against GTSAM alone (`LevenbergMarquardtOptimizer.optimize()` on
  the same factors, initial values and parameters), both timed in the same process;
- online: full iSAM2 and fixed lags; per-step latency and CPU time over the first and last
  tenth of the steps (`graphloc.pipelines.report.latency_trend`), the slowest step, real-time
  factor, ATE per robot against batch, resident memory sampled along the run;
- long run: the run replayed `copies` times with the clock shifted by its duration (every
  factor re-keyed onto new poses and anchors, `replay_graph`), solved online with the lag;
- why a lag loses accuracy to batch: each robot's longest stretch without a landmark or
  teammate measurement (`observation_gaps`) and the online / batch error per tenth of its
  poses (`tenth_error_ratios`);
- CPU costs on a shared machine: the default lag solved again and again, each step's least
  CPU time over the repeats (`repeated_online_cpu`).
"""

from __future__ import annotations

import os
import time
from dataclasses import replace

import gtsam
import numpy as np

from benchmarks.front_door import truth_at
from graphloc.keys import decode, landmark_key, pose_key
from graphloc.pipelines.report import evaluate, latency_trend
from graphloc.pipelines.team_graph import ANCHOR_BASE, TeamGraph, solve


def rss_mb() -> float:
    """Resident set size of this process [MB] (Linux /proc)."""
    with open("/proc/self/statm") as fh:
        pages = int(fh.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 1e6


def gtsam_only_batch(graph: TeamGraph, initial: dict | None = None) -> dict:
    """GTSAM alone on the batch problem graphloc solves: the graph's factors in step order,
    initial values `initial` (key -> value; None: the graph's guess), the LM parameters
    `Session` uses; wall and CPU time of `optimize()` (graph assembly not counted)."""
    start = graph.initial if initial is None else initial
    cfg = graph.config.session_config("batch", graph.precision)
    factors = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for _, group in graph.steps:
        for f, _ in group:
            factors.add(f)
            for key in f.keys():
                if not values.exists(key):
                    values.insert(key, _as_value(start[key]))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(cfg.lm_max_iterations)
    params.setRelativeErrorTol(cfg.lm_relative_error_tol)
    params.setAbsoluteErrorTol(cfg.lm_absolute_error_tol)
    t0, c0 = time.perf_counter(), time.process_time()
    optimizer = gtsam.LevenbergMarquardtOptimizer(factors, values, params)
    result = optimizer.optimize()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {
        "wall_s": wall,
        "cpu_s": cpu,
        "iterations": int(optimizer.iterations()),
        "error": float(factors.error(result)),
        "factors": int(factors.size()),
        "variables": int(values.size()),
    }


def _as_value(v):
    return v if isinstance(v, gtsam.Pose3) else np.asarray(v, dtype=float)


def replay_graph(graph: TeamGraph, copies: int) -> TeamGraph:
    """The run `copies` times in a row: copy c's clock shifted by c times the run's span (a
    whole number of keyframe steps), its poses and landmark anchors re-keyed onto new indices;
    every robot restarts at its initial pose (its prior is part of each copy)."""
    starts = [t[0] for t in graph.node_times if len(t)]
    ends = [t[-1] for t in graph.node_times if len(t)]
    dt = graph.config.keyframe_dt
    span = np.ceil((max(ends) - min(starts)) / dt + 1) * dt
    sizes = [len(t) for t in graph.node_times]
    anchors = max(
        [
            decode(k)[1] - ANCHOR_BASE + 1
            for k in graph.initial
            if decode(k)[0] == "l" and decode(k)[1] >= ANCHOR_BASE
        ],
        default=0,
    )

    def shift(key: int, c: int) -> int:
        kind, r, k = decode(key)
        if kind == "x":
            return pose_key(r, k + c * sizes[r])
        if kind == "l" and r >= ANCHOR_BASE:
            return landmark_key(r + c * anchors)
        return key

    steps, initial = [], {}
    for c in range(copies):
        for t, group in graph.steps:
            steps.append(
                (
                    t + c * span,
                    [
                        (f if c == 0 else f.rekey([shift(k, c) for k in f.keys()]), kind)
                        for f, kind in group
                    ],
                )
            )
        for key, value in graph.initial.items():
            initial[shift(key, c)] = value
    node_times = [np.concatenate([t + c * span for c in range(copies)]) for t in graph.node_times]
    step_rel = [list(s) * copies for s in graph.step_rel]
    for r, s in enumerate(step_rel):
        for c in range(1, copies):
            if sizes[r]:
                s[c * sizes[r]] = None  # no odometry across the replay's seam
    return replace(
        graph,
        node_times=node_times,
        initial=initial,
        steps=steps,
        step_rel=step_rel,
        factor_types=list(graph.factor_types) * copies,
        decisions=[],
        counts={**graph.counts, "steps": len(steps), "copies": copies},
    )


def online_profile(graph: TeamGraph, lag: float | None, rss_every: int = 250, **config) -> tuple:
    """Solve online with `lag` (and `config`: other GraphConfig fields, e.g.
    relinearize_threshold); resident memory [MB] sampled every `rss_every` steps.
    Returns (TeamResult, CPU seconds of the solve, (steps, MB) samples)."""
    samples = []

    def on_step(i):
        if i % rss_every == 0:
            samples.append((i, rss_mb()))

    c0 = time.process_time()
    cfg = replace(graph.config, lag=lag, **config)
    result = solve(replace(graph, config=cfg), "online", on_step=on_step)
    return result, time.process_time() - c0, np.array(samples, dtype=float).reshape(-1, 2)


def marginalization_split(result) -> dict:
    """Fixed lag: the steps that marginalized (the live-variable count drops: a batch of
    `marginalize_every` seconds left the window) apart from the others -- their share of the
    steps in the first and last tenth, and the p95 CPU [ms] of the other steps in each tenth
    with their ratio. A share above 5 % puts the p95 of a tenth on marginalizing steps; the
    first tenth has fewer of them (the window fills for `lag` seconds first), so the p95
    ratio of a run can reflect the marginalization batch size rather than growth."""
    log = result.step_log
    n = len(log) // 10
    marg = np.r_[False, np.diff(log[:, 5]) < 0]
    out = {"marginalizing_steps": int(marg.sum())}
    for name, part in (("first10", slice(0, n)), ("last10", slice(len(log) - n, len(log)))):
        m, cpu = marg[part], log[part, 3]
        out[f"share_{name}"] = float(m.mean())
        out[f"cpu_p95_{name}_other_ms"] = float(np.percentile(cpu[~m], 95) * 1e3)
        out[f"cpu_p95_{name}_marginalizing_ms"] = (
            float(np.percentile(cpu[m], 95) * 1e3) if m.any() else None
        )
    out["cpu_p95_other_last_over_first"] = out["cpu_p95_last10_other_ms"] / max(
        out["cpu_p95_first10_other_ms"], 1e-12
    )
    return out


def memory_slope(samples: np.ndarray) -> float | None:
    """Least-squares slope of resident memory over the second half of the run [MB per 1,000
    steps] (the first half includes the allocator's warm-up)."""
    half = samples[len(samples) // 2 :]
    if len(half) < 3:
        return None
    return float(np.polyfit(half[:, 0], half[:, 1], 1)[0] * 1000)


def online_summary(result, cpu_s: float, samples: np.ndarray, run, batch_ate: dict | None) -> dict:
    """Latency trend, real-time factors, memory, ATE (and ATE over batch ATE) per robot."""
    metrics = evaluate(result, run, align="se2") if batch_ate is not None else None
    log = result.step_log
    duration = float(log[-1, 1] - log[0, 1]) if len(log) else 0.0
    out = {
        "lag_s": result.lag,
        "steps": int(len(log)),
        "wall_s": result.wall_s,
        "cpu_s": cpu_s,
        "realtime_factor": duration / max(result.wall_s, 1e-12),
        "realtime_factor_cpu": duration / max(cpu_s, 1e-12),
        "latency_ms": {
            "mean": float(log[:, 2].mean() * 1e3),
            "p95": float(np.percentile(log[:, 2], 95) * 1e3),
            "max": float(log[:, 2].max() * 1e3),
        },
        "dropped_across_lag": result.dropped,
        "memory_mb_per_1000_steps": memory_slope(samples),
        "rss_mb_end": float(samples[-1, 1]) if len(samples) else None,
    }
    out["trend"] = latency_trend(result)
    if result.lag and len(log) >= 10:
        out["marginalization"] = marginalization_split(result)
    if metrics is not None:
        ate = {
            name: e["online"]["ate_rmse"]
            for name, e in metrics["per_robot"].items()
            if isinstance(e.get("online"), dict) and "ate_rmse" in e["online"]
        }
        out["ate_rmse_m"] = ate
        out["ate_over_batch"] = {
            name: a / batch_ate[name] for name, a in ate.items() if name in batch_ate
        }
    return out


def observation_gaps(graph: TeamGraph, kinds=("landmark", "inter_robot")) -> list:
    """Per robot: the longest stretch [s] of the run during which no factor of `kinds` (the
    measurements that tie a robot to the map or to a teammate; odometry does not) touches one
    of its poses, and when it starts (seconds from the run's first step). A fixed lag shorter
    than a stretch cannot carry the measurements that end it back to the poses inside it: the
    batch solve can, so the stretch bounds what any lag below it can match."""
    start = graph.steps[0][0] if graph.steps else 0.0
    end = graph.steps[-1][0] if graph.steps else 0.0
    seen: list[list] = [[] for _ in graph.node_times]
    for t, group in graph.steps:
        for f, kind in group:
            if kind in kinds:
                for key in f.keys():
                    what, r, _ = decode(key)
                    if what == "x":
                        seen[r].append(t - start)
    out = []
    for times in seen:
        marks = np.unique(np.r_[0.0, np.asarray(times, dtype=float), end - start])
        gaps = np.diff(marks)
        i = int(np.argmax(gaps)) if len(gaps) else 0
        out.append(
            {
                "observed_steps": len(times),
                "longest_gap_s": float(gaps[i]) if len(gaps) else 0.0,
                "gap_start_s": float(marks[i]) if len(gaps) else 0.0,
            }
        )
    return out


def tenth_error_ratios(online, batch, run) -> list:
    """Per robot: the RMS position error [m] (against the ground truth nearest in time, no
    alignment) of the online estimate over that of the batch estimate, in each tenth of the
    robot's poses -- where along the run the online estimate loses to the batch one."""
    out = []
    for r in range(len(run.robots)):
        if run.groundtruth[r] is None or len(online.node_times[r]) < 10:
            out.append(None)
            continue
        truth = truth_at(run, r, online.node_times[r])
        err = {
            name: np.linalg.norm(res.estimate[r][:, :3] - truth, axis=1)
            for name, res in (("online", online), ("batch", batch))
        }
        parts = np.array_split(np.arange(len(truth)), 10)
        out.append(
            [
                float(
                    np.sqrt(np.nanmean(err["online"][p] ** 2))
                    / max(np.sqrt(np.nanmean(err["batch"][p] ** 2)), 1e-12)
                )
                for p in parts
            ]
        )
    return out


def repeated_online_cpu(graph: TeamGraph, lag: float, repeats: int) -> dict:
    """The same online solve `repeats` times, for CPU costs on a shared machine: other processes
    only add to a step's thread CPU time (cache and core contention), so the least time of each
    step over the repeats estimates its own cost, as `timeit` takes the best of n. From those
    per-step minima: the slowest step and the p95 of the first and last tenth [ms]; the least
    total CPU of a solve [s] and its real-time factor; and whether every repeat gave the same
    estimate (max absolute difference of the pose rows)."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    steps, totals, first, diff = [], [], None, 0.0
    for _ in range(repeats):
        result, cpu, _ = online_profile(graph, lag)
        steps.append(result.step_log[:, 3])
        totals.append(cpu)
        if first is None:
            first = result
            continue
        for a, b in zip(first.estimate, result.estimate, strict=True):
            ok = np.isfinite(a) & np.isfinite(b)
            diff = max(diff, float(np.max(np.abs(a[ok] - b[ok]), initial=0.0)))
    least = np.min(np.vstack(steps), axis=0)
    log = first.step_log
    n = max(len(least) // 10, 1)
    p95 = [float(np.percentile(x, 95) * 1e3) for x in (least[:n], least[-n:])]
    duration = float(log[-1, 1] - log[0, 1]) if len(log) else 0.0
    return {
        "lag_s": lag,
        "repeats": repeats,
        "cpu_s_least": float(min(totals)),
        "cpu_s_each": [float(c) for c in totals],
        "realtime_factor_cpu": duration / max(min(totals), 1e-12),
        "cpu_max_ms": float(least.max() * 1e3),
        "cpu_p95_first10_ms": p95[0],
        "cpu_p95_last10_ms": p95[1],
        "cpu_p95_last_over_first": p95[1] / max(p95[0], 1e-12),
        "max_estimate_difference": diff,
    }
