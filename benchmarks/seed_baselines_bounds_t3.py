"""Issue 20: why no reading reproduces seed 000 (000_05137a0a9c449be3.txt) Table III (Sec.
VI-B, the belief vector), as a bound rather than a sentence.

The belief vector's trace does not depend on beliefs: every tracked solution goes to its
nearest candidate of the next frame if closer than the 0.05 m gate (scaled by the elapsed
time) with optical axes dot >= 0.85 (benchmarks.baselines.belief_vector). So whether the
genuine solution's track survives a frame depends on the P3P candidates alone -- on the
trajectory and the image noise, not on the likelihood, the odometry reading or the action
frame. `tracing_events` checks every frame of one run: the genuine candidate of frame k-1
traced into frame k is lost (outside the gate) or jumps (onto a pseudo solution). A run that
locks onto the genuine solution and never relocalizes (the paper: "it never has a belief
under the threshold" after converging) must lock after its last such frame L, so over the
runs of a cell, mean updates to converge >= mean L (0 without such a frame) under EVERY
reading of the belief vector: where that exceeds Table III's value by more than 10 %, the
cell's number and "never" cannot both hold at that image noise.

Below that noise, `table3_intervals` gives per reading the image stds where each cell's mean
updates to converge meets Table III within 10 % (t interval over the runs), no run
relocalizes and no first lock is wrong (brackets of benchmarks.seed_baselines_bounds).
"""

from __future__ import annotations

import itertools
import time

import numpy as np
from scipy import stats

from benchmarks.baselines.belief_vector import BeliefVectorConfig
from graphloc.datasets.feng import FengProbabilisticConfig, FengProbabilisticScenario
from benchmarks.trials import TrialExecutor
from benchmarks import seed_baselines as sb
from benchmarks.hypotheses import CELLS, PAPER_TABLE_III
from benchmarks.seed_baselines_bounds import (
    CONFIDENCE,
    disjoint_pair,
    interval,
    side,
    table1_intervals,
)

# the sweep's image stds plus smaller ones down to zero noise, ascending
T3_BOUND_SIGMAS = tuple(
    sorted({0.0, 0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.03} | set(sb.T3_PIXEL_SIGMAS))
)


def tracing_events(
    ceiling: str, curve: str, seed: int, pixel_sigma: float = 0.0, config=BeliefVectorConfig()
) -> dict:
    """The seed's trace of the genuine solution along one Sec. VI-B run (the sweep's
    simulation at `pixel_sigma`): per frame k >= 1 the genuine candidate of frame k-1 traced
    to its nearest candidate of frame k. lost: outside the gate or axes apart (also when the
    genuine root has left the real solutions); jumped: traced, but onto a pseudo solution;
    ambiguous: a pseudo solution also passes the gate and the axis test (margin: its distance
    minus the genuine one's); merges: frames with two candidates closer than the gate."""
    run = FengProbabilisticScenario.simulate(
        FengProbabilisticConfig(ceiling=ceiling, curve=curve, seed=seed, pixel_sigma=pixel_sigma)
    )
    lost, jumped, ambiguous, margins, merges, resized = [], [], [], [], [], []
    pair_min = np.inf
    for k in range(1, len(run)):
        prev, cur = run.candidates[k - 1], run.candidates[k]
        if not len(prev) or not len(cur):
            lost.append(k)
            continue
        g0, g1 = prev.meta["genuine"], cur.meta["genuine"]
        dt = run.times[k] - run.times[k - 1]
        gate = config.gate_distance * max(dt / config.gate_interval, 1.0)
        d = np.linalg.norm(cur.t - prev.t[g0], axis=1)
        dots = cur.R[:, :, 2] @ prev.R[g0][:, 2]
        passes = (d < gate) & (dots >= config.min_normal_dot)
        nn = int(np.argmin(d))
        if not passes[nn]:
            lost.append(k)
        elif nn != g1:
            jumped.append(k)
        others = passes & (np.arange(len(cur)) != g1)
        if passes[g1] and others.any():
            ambiguous.append(k)
            margins.append(float(d[others].min() - d[g1]))
        if len(cur) > 1:
            pd = np.linalg.norm(cur.t[:, None] - cur.t[None], axis=2)[np.triu_indices(len(cur), 1)]
            pair_min = min(pair_min, float(pd.min()))
            merges += [k] if (pd < gate).any() else []
        if len(cur) != len(prev):
            resized.append(k)
    return {
        "frames": len(run),
        "lost": lost,
        "jumped": jumped,
        "ambiguous": ambiguous,
        "ambiguous_margin_min_m": min(margins) if margins else None,
        "merges": merges,
        "size_changes": len(resized),
        "closest_pair_m": pair_min,
        "genuine_error_max_m": float(
            max(c.meta["genuine_error"] for c in run.candidates if len(c))
        ),
        "trajectory_digest": float(np.abs(run.t_wc).sum()),
    }


def _trace_job(job) -> dict:
    ceiling, curve, i, sigma = job
    seed = 1000 * CELLS.index((ceiling, curve)) + i  # the sweep's seeds (offset 0)
    return {
        "cell": f"{ceiling}/{curve}",
        "sigma": sigma,
        **tracing_events(ceiling, curve, seed, sigma),
    }


def _cell_summary(ev: list, paper: float) -> dict:
    """Per cell: runs that lose (or jump) the genuine trace, and the bound on mean updates to
    converge of runs that lock correctly and never relocalize (lost frames: the committed
    track drops, a relocalization) or also never leave the genuine solution (lost or jumped)."""

    def bound(keys):
        return float(np.mean([max([0] + [k for key in keys for k in e[key]]) for e in ev]))

    lost_bound, left_bound = bound(("lost",)), bound(("lost", "jumped"))
    return {
        "runs": len(ev),
        "runs_lost": sum(bool(e["lost"]) for e in ev),
        "runs_jumped": sum(bool(e["jumped"]) for e in ev),
        "runs_with_event": sum(bool(e["lost"] or e["jumped"]) for e in ev),
        "updates_bound": lost_bound,
        "updates_bound_left": left_bound,
        "paper": paper,
        "bound_exceeds_paper": lost_bound > (1 + sb.REPRODUCE_TOL) * paper,
        "bound_left_exceeds_paper": left_bound > (1 + sb.REPRODUCE_TOL) * paper,
        "genuine_error_max_m": max(e["genuine_error_max_m"] for e in ev),
    }


def table3_traces(runs: int, workers: int = 1, sigmas=T3_BOUND_SIGMAS, progress=True) -> dict:
    """`tracing_events` for every cell x `runs` runs (the sweep's seeds and noise draws) at
    every image std of `sigmas`: per std and cell the runs whose genuine trace is lost or
    jumps, and the bound on mean updates to converge of a run that locks correctly and never
    relocalizes (module docstring); the noise-free details per cell."""
    jobs = [(ce, cu, i, s) for s in sigmas for ce, cu in CELLS for i in range(runs)]
    with TrialExecutor(workers, progress=progress) as ex:
        events = list(ex.imap(_trace_job, jobs, desc="Table III genuine traces"))
    by_sigma = []
    for s in sigmas:
        cells = {}
        for ceiling, curve in CELLS:
            name = f"{ceiling}/{curve}"
            ev = [e for e in events if e["cell"] == name and e["sigma"] == s]
            cells[name] = _cell_summary(ev, PAPER_TABLE_III[(ceiling, curve)])
        by_sigma.append(
            {
                "pixel_sigma": s,
                "cells": cells,
                "runs_lost": sum(c["runs_lost"] for c in cells.values()),
                "runs_with_event": sum(c["runs_with_event"] for c in cells.values()),
                "cells_bound_exceeds_paper": sum(c["bound_exceeds_paper"] for c in cells.values()),
                "cells_bound_left_exceeds_paper": sum(
                    c["bound_left_exceeds_paper"] for c in cells.values()
                ),
            }
        )
    noise_free = {}
    for ceiling, curve in CELLS:
        name = f"{ceiling}/{curve}"
        ev = [e for e in events if e["cell"] == name and e["sigma"] == 0.0]
        if not ev:
            continue
        noise_free[name] = {
            "frames": ev[0]["frames"],
            "identical_trajectories": len({e["trajectory_digest"] for e in ev}) == 1,
            "jump_frames": sorted({k for e in ev for k in e["jumped"]}),
            "ambiguous_frames": max(len(e["ambiguous"]) for e in ev),
            "ambiguous_margin_min_m": min(
                (
                    e["ambiguous_margin_min_m"]
                    for e in ev
                    if e["ambiguous_margin_min_m"] is not None
                ),
                default=None,
            ),
            "merge_frames": max(len(e["merges"]) for e in ev),
            "size_changes": max(e["size_changes"] for e in ev),
            "closest_pair_m": min(e["closest_pair_m"] for e in ev),
        }
    return {
        "sigmas": list(sigmas),
        "runs": runs * len(CELLS),
        "by_sigma": by_sigma,
        "noise_free": noise_free,
    }


def _t_interval(cell: dict) -> tuple[float, float] | None:
    m = cell.get("mean_updates_to_converge")
    s, n = cell.get("std_updates_to_converge"), cell.get("converged_runs")
    if m is None:
        return None
    if s is None or not n or n < 2:
        return m, m
    half = stats.t.ppf(0.5 + CONFIDENCE / 2, n - 1) * s / np.sqrt(n)
    return m - half, m + half


def table3_intervals(rows: list, sigmas: tuple) -> list:
    """Per belief-vector reading (odometry, likelihood, action frame): per cell the image
    stds where the mean updates to converge meets Table III within 10 % (t interval), where
    no run relocalizes and where no first lock is wrong, over `sigmas` (ascending); whether
    each cell's mean is monotone in the std; a disjoint pair over all of them."""
    out = []
    for m, lik, frame in itertools.product(sb.T3_ODOMETRY, sb.T3_LIKELIHOODS, sb.T3_ACTION_FRAMES):
        sel = {
            x["pixel_sigma"]: x
            for x in rows
            if (x["odometry_model"], x["likelihood"], x["action_frame"]) == (m, lik, frame)
        }
        seq = [sel[s] for s in sigmas]
        per, monotone, means, met = {}, {}, {}, np.zeros(len(sigmas), dtype=int)
        for cell in seq[0]["cells"]:
            paper = seq[0]["cells"][cell]["paper"]
            sides = [
                None if c is None else side((0.0, *c), paper)
                for c in map(_t_interval, (x["cells"][cell] for x in seq))
            ]
            per[cell] = interval(sigmas, [x == 0 for x in sides], sides)
            met += [x == 0 for x in sides]
            means[cell] = [x["cells"][cell]["mean_updates_to_converge"] for x in seq]
            monotone[cell] = _monotone(means[cell])
        per["no_relocalization"] = interval(
            sigmas, [x["runs_with_relocalization"] == 0 for x in seq]
        )
        per["no_wrong_lock"] = interval(sigmas, [x["wrong_locks"] == 0 for x in seq])
        out.append(
            {
                "odometry_model": m,
                "likelihood": lik,
                "action_frame": frame,
                "intervals": per,
                "monotone": monotone,
                "mean_updates": means,
                "cells_met": met.tolist(),
                "relocalized_runs": [x["runs_with_relocalization"] for x in seq],
                "wrong_locks": [x["wrong_locks"] for x in seq],
                "disjoint": disjoint_pair(per),
            }
        )
    return out


def _monotone(values: list) -> str:
    x = np.array([np.nan if v is None else v for v in values], dtype=float)
    d = np.diff(x[np.isfinite(x)])
    if d.size and (d >= 0).all():
        return "increasing"
    if d.size and (d <= 0).all():
        return "decreasing"
    return "no"


def table3_bounds(runs: int, workers: int, progress: bool = True) -> dict:
    """`table3_traces` and the belief vector on T3_BOUND_SIGMAS (sb.table3_sweep, the sweep's
    seeds) with its per-reading intervals (`table3_intervals`), `runs` runs per cell."""
    t0 = time.perf_counter()
    traces = table3_traces(runs, workers, T3_BOUND_SIGMAS, progress)
    rows = sb.table3_sweep(runs, workers, progress=progress, sigmas=T3_BOUND_SIGMAS)
    return {
        "sigmas": list(T3_BOUND_SIGMAS),
        "runs_per_cell": runs,
        "confidence": CONFIDENCE,
        "traces": traces,
        "rows": rows,
        "readings": table3_intervals(rows, T3_BOUND_SIGMAS),
        "wall_time_s": time.perf_counter() - t0,
    }


def bounds(sizes: dict, workers: int, progress: bool = True) -> dict:
    """Both seed 000 bounds at the sweep's sizes (keys t1_trials, t3_runs)."""
    return {
        "table1": table1_intervals(sizes["t1_trials"], workers, progress=progress),
        "table3": table3_bounds(sizes["t3_runs"], workers, progress),
    }
