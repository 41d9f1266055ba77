"""Issue 20: why no reading reproduces seed 000 (000_05137a0a9c449be3.txt) Tables I and III,
as bounds rather than sentences (graphloc.experiments.seed_baselines sweeps the readings).

Table III (Sec. VI-B, belief vector). Relocalizations come either from the geometry of the
P3P solutions along the stated trajectories or from the image noise. `tracing_events` runs
the seed's nearest-neighbour trace (Sec. VI-B: same track when closer than the 0.05 m gate,
scaled by the elapsed time, and optical axes with dot >= 0.85; graphloc.baselines.
belief_vector) on noise-free P3P candidates: a frame where the genuine solution's trace is not
the genuine solution (lost: outside the gate; jumped: onto a pseudo solution) loses the
genuine track for ANY image noise level near zero, likelihood, odometry reading or action
frame; so runs with such an event bound the relocalizations from below. `table3_bounds` adds
the image-noise side: every belief-vector reading on a finer image-noise grid (same runs as
the sweep, including zero noise), and per reading the intervals of image std in which each
cell's mean updates to converge is within 10 % of Table III (t interval over the runs),
runs never relocalize, and first locks are never wrong.

Table I (Sec. VI-A, P3P + straight-line test). For a fixed geometric reading (lateral noise,
orientation) every Table I number is monotone in the image std (the noise draws scale with
it). `table1_intervals` evaluates the seed baseline on a fine log grid of image std and
returns, per number, the grid points where its confidence interval (Clopper-Pearson for the
correct count, a normal interval for means, the point value for stds, the maximum and the
runner-up) meets the paper's +-10 % band. With monotonicity the true interval lies between
the neighbouring grid points that miss the band; two such brackets that do not overlap prove
that no image std reproduces both numbers under that reading.
"""

from __future__ import annotations

import itertools
import time

import numpy as np
from scipy import stats

from graphloc.baselines.belief_vector import BeliefVectorConfig
from graphloc.datasets.feng import FengProbabilisticConfig, FengProbabilisticScenario
from graphloc.executor import Executor
from graphloc.experiments.hypotheses import CELLS, PAPER_TABLE_III
from graphloc.experiments.seed000_table1 import PAPER_TABLE_I
from graphloc.experiments import seed_baselines as sb

# Table I: image std grid, 16 points per decade (a step of x1.155 is finer than the band's
# 1.1 / 0.9 = x1.22, so a number growing like the std cannot jump over the band)
T1_BOUND_SIGMAS = tuple(float(f"{s:.4g}") for s in np.logspace(-4, 0, 65))
# Table III: the sweep's image stds plus smaller ones down to zero noise
T3_BOUND_SIGMAS = (0.0, 0.005, 0.01, 0.02, 0.03) + sb.T3_PIXEL_SIGMAS
CONFIDENCE = 0.95
# Table I numbers: (key, paper value)
T1_NUMBERS = {
    "correct": PAPER_TABLE_I["success"],
    "C2_mean": PAPER_TABLE_I["C2"][0],
    "C2_std": PAPER_TABLE_I["C2"][1],
    "C3_mean": PAPER_TABLE_I["C3"][0],
    "C3_std": PAPER_TABLE_I["C3"][1],
    "C_mean": PAPER_TABLE_I["C"][0],
    "C_std": PAPER_TABLE_I["C"][1],
    "line_genuine_mean": sb.PAPER_LINE_ERRORS["genuine_mean"],
    "line_genuine_max": sb.PAPER_LINE_ERRORS["genuine_max"],
    "line_second_mean": sb.PAPER_LINE_ERRORS["second_mean"],
}


# ---- intervals of a monotone family --------------------------------------------------------
def interval(sigmas, ok, side=None) -> dict | None:
    """The grid points where a number meets its band (`ok`, per sigma, sigmas ascending):
    inner [lo, hi] (first and last meeting point) and the outer bracket (the neighbouring grid
    points that miss it; 0 / inf at the ends), which holds the true interval when the number
    is monotone in sigma; contiguous = no grid point between lo and hi misses it; jumps
    (with `side`, -1 / +1 where a point misses below / above the band): neighbouring grid
    points missing on opposite sides, i.e. the number crossed the band between them, where a
    grid point could have met it. None if no grid point meets the band (and none is jumped)."""
    sigmas, ok = np.asarray(sigmas, dtype=float), np.asarray(ok, dtype=bool)
    jumps = _jumps(sigmas, side)
    hit = np.flatnonzero(ok)
    if not hit.size and not jumps:
        return None
    out = {"jumps": jumps, "lo": None, "hi": None, "outer_lo": np.inf, "outer_hi": 0.0}
    if hit.size:
        i, j = int(hit[0]), int(hit[-1])
        out.update(
            lo=float(sigmas[i]),
            hi=float(sigmas[j]),
            outer_lo=float(sigmas[i - 1]) if i > 0 else 0.0,
            outer_hi=float(sigmas[j + 1]) if j + 1 < len(sigmas) else float("inf"),
        )
    # a band crossed between two grid points widens the bracket to them
    out["outer_lo"] = min([out["outer_lo"]] + [x[0] for x in jumps])
    out["outer_hi"] = max([out["outer_hi"]] + [x[1] for x in jumps])
    out["contiguous"] = bool(hit.size) and not jumps and bool(ok[hit[0] : hit[-1] + 1].all())
    return out


def _jumps(sigmas: np.ndarray, side) -> list:
    if side is None:
        return []
    s = np.asarray([np.nan if x is None else x for x in side], dtype=float)
    flip = s[:-1] * s[1:] < 0
    return [[float(sigmas[k]), float(sigmas[k + 1])] for k in np.flatnonzero(flip)]


def disjoint_pair(intervals: dict) -> dict | None:
    """Two numbers whose outer brackets do not overlap (the one whose bracket starts last vs
    the one whose bracket ends first), with the gap; an empty interval alone also proves it
    (returned as {"empty": name}). None when all brackets share a point."""
    empty = [k for k, v in intervals.items() if v is None]
    if empty:
        return {"empty": empty}
    starts = max(intervals, key=lambda k: intervals[k]["outer_lo"])
    ends = min(intervals, key=lambda k: intervals[k]["outer_hi"])
    a, b = intervals[ends]["outer_hi"], intervals[starts]["outer_lo"]
    if a > b:
        return None
    return {"ends_first": ends, "below": a, "starts_last": starts, "above": b, "ratio": b / a}


# ---- Table I -------------------------------------------------------------------------------
def _binomial_ci(k: int, n: int) -> tuple[float, float]:
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=CONFIDENCE, method="exact")
    return float(ci.low), float(ci.high)


def table1_values(row: dict) -> dict:
    """Per Table I number of one sweep row: (value, ci_low, ci_high) in the paper's units
    (correct per 1000; relative errors; metres), or None when the row has no value."""
    z = stats.norm.ppf(0.5 + CONFIDENCE / 2)
    n = row["correct"]
    out = {}
    lo, hi = _binomial_ci(n, row["trials"])
    scale = 1000.0 / row["trials"]
    out["correct"] = (n * scale, 1000.0 * lo, 1000.0 * hi)
    for cam, count in (("C2", n), ("C3", n), ("C", 3 * n)):
        pair = row[cam]
        if pair is None:
            out[f"{cam}_mean"] = out[f"{cam}_std"] = None
            continue
        half = z * pair[1] / np.sqrt(max(count, 1))
        out[f"{cam}_mean"] = (pair[0], pair[0] - half, pair[0] + half)
        out[f"{cam}_std"] = (pair[1], pair[1], pair[1])
    m, s = row["line_genuine_mean_m"], row.get("line_genuine_std_m")
    half = z * s / np.sqrt(max(n, 1)) if m is not None and s is not None else 0.0
    out["line_genuine_mean"] = None if m is None else (m, m - half, m + half)
    mx = row["line_genuine_max_m"]
    out["line_genuine_max"] = None if mx is None else (mx, mx, mx)
    second = [row[k] for k in ("line_second_mean_m", "line_second_pseudo_middle_mean_m")]
    second = [x for x in second if x is not None]
    paper2 = T1_NUMBERS["line_second_mean"]
    out["line_second_mean"] = (
        None if not second else (lambda x: (x, x, x))(min(second, key=lambda x: abs(x - paper2)))
    )
    return out


def side(value, paper: float) -> int | None:
    """0 when the value's confidence interval meets the paper's +-10 % band, -1 / +1 when it
    lies below / above it, None without a value."""
    if value is None:
        return None
    _, lo, hi = value
    if hi < (1 - sb.REPRODUCE_TOL) * paper:
        return -1
    return 1 if lo > (1 + sb.REPRODUCE_TOL) * paper else 0


def table1_intervals(
    trials: int,
    workers: int,
    sigmas: tuple = T1_BOUND_SIGMAS,
    readings=None,
    progress: bool = True,
) -> dict:
    """The seed baseline (sb.table1_seed, seed 0 as the sweep) on the `sigmas` grid for every
    geometric reading (lateral std, orientation), and per reading and Table I number the
    interval of image std in which it meets the paper within 10 % (`interval`), whether it is
    monotone over the grid, and a pair of numbers with disjoint brackets (`disjoint_pair`)."""
    t0 = time.perf_counter()
    sigmas = tuple(sorted(sigmas))
    readings = list(readings or itertools.product(sb.T1_LATERAL_SIGMAS, sb.T1_ORIENTATIONS))
    jobs = [(s, lat, o, trials, 0) for (lat, o) in readings for s in sigmas]
    with Executor(workers, progress=progress) as ex:
        rows = list(ex.imap(sb._t1_job, jobs, desc="Table I intervals"))
    out = []
    for lat, orient in readings:
        sel = [r for r in rows if (r["lateral_sigma"], r["orientation"]) == (lat, orient)]
        sel.sort(key=lambda r: r["pixel_sigma"])
        values = [table1_values(r) for r in sel]
        per_number, monotone, series = {}, {}, {}
        for key, paper in T1_NUMBERS.items():
            v = [x[key] for x in values]
            sides = [side(x, paper) for x in v]
            per_number[key] = interval(sigmas, [x == 0 for x in sides], sides)
            point = np.array([np.nan if x is None else x[0] for x in v])
            monotone[key] = _monotone(point)
            series[key] = [None if x is None else list(x) for x in v]
        both = {k: per_number[k] for k in ("correct", "C_mean")}
        out.append(
            {
                "lateral_sigma": lat,
                "orientation": orient,
                "intervals": per_number,
                "monotone": monotone,
                "disjoint": disjoint_pair(per_number),
                "disjoint_correct_vs_C_mean": disjoint_pair(both),
                "series": series,
            }
        )
    return {
        "sigmas": list(sigmas),
        "trials": trials,
        "confidence": CONFIDENCE,
        "paper": T1_NUMBERS,
        "readings": out,
        "wall_time_s": time.perf_counter() - t0,
    }


def _monotone(x: np.ndarray) -> str:
    """'increasing' / 'decreasing' (non-strict, over the finite points), or 'no'."""
    d = np.diff(x[np.isfinite(x)])
    if d.size == 0:
        return "no"
    if (d >= 0).all():
        return "increasing"
    if (d <= 0).all():
        return "decreasing"
    return "no"


# ---- Table III -----------------------------------------------------------------------------
def tracing_events(ceiling: str, curve: str, seed: int, config=BeliefVectorConfig()) -> dict:
    """The seed's trace of the genuine solution along one Sec. VI-B run on noise-free P3P
    candidates: per frame k >= 1 the genuine candidate of frame k-1 traced to its nearest
    candidate of frame k (gate and optical-axis test as graphloc.baselines.belief_vector).
    lost: outside the gate or axes apart; jumped: traced, but onto a pseudo solution;
    ambiguous: a pseudo solution also passes the gate and the axis test (the margin: its
    distance minus the genuine one's, the room the image noise has before the trace flips);
    merges: frames with two candidates closer than the gate; size changes of the set."""
    run = FengProbabilisticScenario.simulate(
        FengProbabilisticConfig(ceiling=ceiling, curve=curve, seed=seed, pixel_sigma=0.0)
    )
    lost, jumped, ambiguous, margins, merges, resized = [], [], [], [], [], []
    pair_min = np.inf
    for k in range(1, len(run)):
        prev, cur = run.candidates[k - 1], run.candidates[k]
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
            if (pd < gate).any():
                merges.append(k)
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
        "genuine_error_max_m": float(max(c.meta["genuine_error"] for c in run.candidates)),
        "trajectory_digest": float(np.abs(run.t_wc).sum()),
    }


def _trace_job(job) -> dict:
    ceiling, curve, i, seed_offset = job
    seed = seed_offset + 1000 * CELLS.index((ceiling, curve)) + i
    return {"cell": f"{ceiling}/{curve}", "run": i, **tracing_events(ceiling, curve, seed)}


def table3_geometry(runs: int, workers: int = 1, progress: bool = True) -> dict:
    """`tracing_events` for every cell x `runs` runs (the sweep's seeds); per cell the runs
    whose genuine trace is lost or jumps (a lower bound on relocalized runs near zero image
    noise, whatever the likelihood, odometry or action frame), and the latest such frame (a
    run that converges correctly and never relocalizes needs its first lock after it)."""
    jobs = [(ceiling, curve, i, 0) for ceiling, curve in CELLS for i in range(runs)]
    with Executor(workers, progress=progress) as ex:
        events = list(ex.imap(_trace_job, jobs, desc="Table III noise-free traces"))
    cells = {}
    for ceiling, curve in CELLS:
        name = f"{ceiling}/{curve}"
        ev = [e for e in events if e["cell"] == name]
        bad = [e for e in ev if e["lost"] or e["jumped"]]
        cells[name] = {
            "runs": len(ev),
            "frames": ev[0]["frames"],
            "identical_trajectories": len({e["trajectory_digest"] for e in ev}) == 1,
            "runs_lost": sum(bool(e["lost"]) for e in ev),
            "runs_jumped": sum(bool(e["jumped"]) for e in ev),
            "runs_with_event": len(bad),
            "last_event_frame": max((max(e["lost"] + e["jumped"]) for e in bad), default=None),
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
            "genuine_error_max_m": max(e["genuine_error_max_m"] for e in ev),
            "paper": PAPER_TABLE_III[(ceiling, curve)],
        }
    total = sum(c["runs"] for c in cells.values())
    return {
        "cells": cells,
        "runs": total,
        "runs_with_event": sum(c["runs_with_event"] for c in cells.values()),
        "runs_lost": sum(c["runs_lost"] for c in cells.values()),
    }


def _t_interval(cell: dict) -> tuple[float, float] | None:
    m, s, n = (
        cell.get(k)
        for k in ("mean_updates_to_converge", "std_updates_to_converge", "converged_runs")
    )
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
        per, monotone, means = {}, {}, {}
        for cell in seq[0]["cells"]:
            paper = seq[0]["cells"][cell]["paper"]
            ci = [_t_interval(x["cells"][cell]) for x in seq]
            sides = [None if c is None else side((0.0, *c), paper) for c in ci]
            per[cell] = interval(sigmas, [x == 0 for x in sides], sides)
            mean = [x["cells"][cell]["mean_updates_to_converge"] for x in seq]
            means[cell] = mean
            monotone[cell] = _monotone(np.array([np.nan if v is None else v for v in mean]))
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
                "relocalized_runs": [x["runs_with_relocalization"] for x in seq],
                "wrong_locks": [x["wrong_locks"] for x in seq],
                "disjoint": disjoint_pair(per),
            }
        )
    return out


def table3_bounds(runs: int, workers: int, progress: bool = True) -> dict:
    """Noise-free tracing (`table3_geometry`) and the belief vector on T3_BOUND_SIGMAS with
    its intervals (`table3_intervals`), `runs` runs per cell (the sweep's seeds)."""
    t0 = time.perf_counter()
    geometry = table3_geometry(runs, workers, progress)
    rows = sb.table3_sweep(runs, workers, progress=progress, sigmas=T3_BOUND_SIGMAS)
    return {
        "sigmas": list(T3_BOUND_SIGMAS),
        "runs_per_cell": runs,
        "confidence": CONFIDENCE,
        "geometry": geometry,
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
