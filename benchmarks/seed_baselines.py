"""Issue 20: under which reading of a seed's setup does OUR implementation of the SEED's method
reproduce the SEED's own numbers? Each seed leaves parts of its simulation open; this module
sweeps them, scores the seed baseline against the paper's numbers, picks the reproducing
reading, and re-runs graphloc under it and under the stated setting.

- Seed 000 (000_05137a0a9c449be3.txt) Table I, Sec. VI-A: the image noise "N(0, 0.5) pixels
  at a random direction" (a standard deviation, a variance, or a radius in another unit: swept
  as an effective std on a log grid) and the climbing robot's "Gaussian noise of N(0, 0.001)
  meter, perpendicular to the direction of X" (std, variance, smaller). Seed baseline: P3P +
  the straight-line test (benchmarks.baselines.straight_line) on the ground triangle of
  graphloc.vision.mutual. Scored on: correct results (the paper: "within a relative error of
  1e-3 ... out of a scale of three meters", i.e. the genuine combination picked and every
  position within 0.003 m -- the 0.003 m threshold of step 5), C2 / C3 / C relative errors,
  the genuine solution's line error (mean 3.19e-4 m) and the runner-up's (mean 0.771 m).
- Seed 000 Table III, Sec. VI-B: image noise as above, the belief vector's likelihood
  (Def. 1 / Def. 2 and how each becomes a similarity: benchmarks.baselines.belief_vector
  LIKELIHOODS) and the odometry noise model ("15% on all three dimensions": per axis or
  isotropic, graphloc.datasets.feng.ODOMETRY_MODELS). Scored on mean updates to converge per
  cell, with wrong first locks and relocalizations ("it never have a belief under the
  threshold" after converging) reported beside.
- Seed 004 (004_fa12d1d18dcbd0db.txt) Table 1, Sec. III: camera height over the LEDs, pixel
  pitch (2/3" sensor kept: the resolution follows), the horizontal offset of the camera from
  the LED triangle (overhead or oblique), and "Gaussian noise with sigma^2 = v" as a variance
  or a standard deviation. Seed baseline: the genuine P3P candidate (graphloc.datasets.kaushik).

Deviation of a number = |ours / paper - 1|; a reading reproduces a table when every scored
number is within REPRODUCE_TOL. The chosen reading minimizes the largest deviation.

    .venv/bin/python scripts/bench_seed_baselines.py [--quick] [--out DIR] [--workers N]

Writes <out>/seed_baselines.json, <out>/results_seed_baselines.png, and
docs/results_seed_baselines.md (+ its PNG) unless --no-docs.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

from benchmarks.baselines.belief_vector import ACTION_FRAMES, BeliefVector, BeliefVectorConfig
from benchmarks.baselines.straight_line import localize_by_straight_line
from graphloc.datasets.feng import FengProbabilisticConfig, FengProbabilisticScenario
from graphloc.datasets.feng_deterministic import (
    ORIENTATIONS,
    Seed000Config,
    TableIConfig,
    ground_triangle,
    simulate_straight_line_trials,
)
from graphloc.datasets.kaushik import FOCALS_MM, NOISE_VARIANCES, KaushikConfig, simulate
from benchmarks.trials import TrialExecutor
from benchmarks import hypotheses
from benchmarks.hypotheses import CELLS, PAPER_TABLE_III, TableIIIConfig
from benchmarks.seed000_table1 import PAPER_TABLE_I
from benchmarks.seed004 import PAPER_SEED004_TABLE_1
from graphloc.geometry.p3p import MAX_CANDIDATES, solve_p3p

REPRODUCE_TOL = 0.10  # issue 20: "within 10% of every number the seed reports"
# Sec. VI-A, text after Table I: line errors of the genuine and the second-best combination [m]
PAPER_LINE_ERRORS = {"genuine_mean": 3.19e-4, "genuine_max": 8.53e-3, "second_mean": 0.771}
CORRECT_TOL = 0.003  # [m] "relative error of 1e-3 ... out of a scale of three meters"

# the sweeps: the stated value first, then the other readings
T1_PIXEL_SIGMAS = (0.5, 0.707, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.002, 0.001)
T1_LATERAL_SIGMAS = (0.001, 0.0316, 0.0003, 0.0)
T1_ORIENTATIONS = ORIENTATIONS
T3_PIXEL_SIGMAS = (0.5, 0.2, 0.1, 0.05)
T3_LIKELIHOODS = (
    "inner_product",
    "inner_product_shifted",
    "distance_angle",
    "distance_angle_inverse",
)
T3_ODOMETRY = ("per_axis", "isotropic")
T3_ACTION_FRAMES = ACTION_FRAMES
S4_HEIGHTS = (1.5, 2.0, 2.5, 3.0)
S4_PITCHES_UM = (5.6, 7.4, 9.9, 13.75)
S4_OFFSETS = (0.0, 0.5, 1.0, 1.5, 2.0)
S4_NOISE_READINGS = ("variance", "std")
SENSOR_WIDTH_MM, SENSOR_HEIGHT_MM = 8.8, 6.6  # 2/3" (graphloc.datasets.kaushik)


def deviation(ours, paper: float) -> float:
    """|ours / paper - 1|; inf when ours is missing."""
    return float(abs(ours / paper - 1.0)) if ours is not None and np.isfinite(ours) else np.inf


# ---- seed 000 Table I --------------------------------------------------------------------------
def table1_seed(
    pixel_sigma: float, lateral_sigma: float, orientation: str, trials: int, seed: int = 0
) -> dict:
    """The seed's deterministic algorithm (Sec. IV) on `trials` Sec. VI-A trials at one
    reading: ground triangle from mutual omni bearings, P3P + straight-line test."""
    cfg = TableIConfig(trials=trials, seed=seed, pixel_sigma=pixel_sigma, workers=1)
    sim = Seed000Config(
        pixel_sigma=pixel_sigma, lateral_sigma=lateral_sigma, orientation=orientation
    )
    pool = simulate_straight_line_trials(int(1.1 * trials) + 10, seed=seed, config=sim)
    tri = ground_triangle(pool.ground, cfg, np.random.default_rng([seed, 1]))
    rows = np.flatnonzero(tri.visible)[:trials]
    truth, est = pool.positions[rows], tri.estimated[rows]
    ok = np.isfinite(est).all(axis=(1, 2))
    choice = localize_by_straight_line(pool.pixels[rows][ok], pool.K, est[ok])
    cand = choice.candidates.t_wc.reshape(-1, 3, MAX_CANDIDATES, 3)
    valid = choice.candidates.valid.reshape(-1, 3, MAX_CANDIDATES)
    dist = np.where(valid, np.linalg.norm(cand - truth[ok][:, :, None], axis=3), np.inf)
    genuine = dist.argmin(axis=2)
    picked = (choice.chosen == genuine).all(axis=1) & choice.found
    err = np.linalg.norm(choice.chosen_positions() - truth[ok], axis=2)
    correct = picked & (np.nan_to_num(err, nan=np.inf).max(axis=1) < CORRECT_TOL)
    ground_err = np.linalg.norm(est[ok] - pool.ground[rows][ok], axis=2)
    n = np.arange(len(genuine))
    line_genuine = choice.errors[n, genuine[:, 0], genuine[:, 1], genuine[:, 2]][correct]
    second = choice.second_error[correct]
    second = second[np.isfinite(second)]
    # the runner-up read as Fig. 4 draws it: 1st and 3rd genuine, the 2nd a pseudo solution
    middle = choice.errors[n, genuine[:, 0], :, genuine[:, 2]]
    middle[n, genuine[:, 1]] = np.inf
    middle = middle.min(axis=1)[correct]
    middle = middle[np.isfinite(middle)]

    def rel(x):
        return (float(x.mean() / cfg.scale), float(x.std() / cfg.scale)) if x.size else None

    return {
        "pixel_sigma": pixel_sigma,
        "lateral_sigma": lateral_sigma,
        "orientation": orientation,
        "trials": int(len(rows)),
        "genuine_picked": int(picked.sum()),
        "correct": int(correct.sum()),
        "C2": rel(ground_err[correct, 1]),
        "C3": rel(ground_err[correct, 2]),
        "C": rel(err[correct].ravel()),
        "line_genuine_mean_m": float(line_genuine.mean()) if line_genuine.size else None,
        "line_genuine_std_m": float(line_genuine.std()) if line_genuine.size else None,
        "line_genuine_max_m": float(line_genuine.max()) if line_genuine.size else None,
        "line_second_mean_m": float(second.mean()) if second.size else None,
        "line_second_pseudo_middle_mean_m": float(middle.mean()) if middle.size else None,
    }


def table1_score(row: dict) -> dict:
    """Deviation of every number the paper reports for Table I (means and stds, the line
    errors, correct results per 1000)."""
    p = PAPER_TABLE_I
    out = {"correct": deviation(1000 * row["correct"] / row["trials"], p["success"])}
    for cam in ("C2", "C3", "C"):
        ours = row[cam] or (None, None)
        out[f"{cam}_mean"] = deviation(ours[0], p[cam][0])
        out[f"{cam}_std"] = deviation(ours[1], p[cam][1])
    out["line_genuine_mean"] = deviation(
        row["line_genuine_mean_m"], PAPER_LINE_ERRORS["genuine_mean"]
    )
    out["line_genuine_max"] = deviation(row["line_genuine_max_m"], PAPER_LINE_ERRORS["genuine_max"])
    # "second best": the runner-up over all combinations, or with only the 2nd snapshot
    # pseudo (Fig. 4); the text allows both, the closer one is scored
    out["line_second_mean"] = min(
        deviation(row[k], PAPER_LINE_ERRORS["second_mean"])
        for k in ("line_second_mean_m", "line_second_pseudo_middle_mean_m")
    )
    return out


def _t1_job(job) -> dict:
    sigma, lateral, orientation, trials, seed = job
    row = table1_seed(sigma, lateral, orientation, trials, seed)
    row["deviation"] = table1_score(row)
    row["max_deviation"] = max(row["deviation"].values())
    return row


# ---- seed 000 Table III ------------------------------------------------------------------------
def _t3_job(job) -> dict:
    """One Sec. VI-B run at one (pixel sigma, odometry model): every likelihood reading's
    belief vector on the same simulated run."""
    sigma, odometry_model, ceiling, curve, run_index, seed_offset = job
    seed = seed_offset + 1000 * CELLS.index((ceiling, curve)) + run_index
    sim = FengProbabilisticConfig(
        ceiling=ceiling, curve=curve, seed=seed, pixel_sigma=sigma, odometry_model=odometry_model
    )
    run = FengProbabilisticScenario.simulate(sim)
    steps = {
        "solution": hypotheses.odometry_steps(run, sim),
        "world": hypotheses.world_odometry_steps(run, sim),
    }
    out = {"key": (sigma, odometry_model, ceiling, curve)}
    for lik, frame in itertools.product(T3_LIKELIHOODS, T3_ACTION_FRAMES):
        engine = BeliefVector(BeliefVectorConfig(likelihood=lik, action_frame=frame))
        r = hypotheses.evaluate(engine, run, steps[frame])
        out[(lik, frame)] = {
            k: r[k] for k in ("converged", "wrong", "relocalizations", "correct_lock")
        }
    return out


def table3_sweep(
    runs: int,
    workers: int,
    seed_offset: int = 0,
    progress: bool = True,
    sigmas: tuple = T3_PIXEL_SIGMAS,
) -> list:
    """Mean updates to converge of the belief vector per (pixel sigma, odometry model,
    likelihood) reading and cell, `runs` runs per cell, and their deviation from Table III."""
    jobs = [
        (s, m, ceiling, curve, i, seed_offset)
        for s, m in itertools.product(sigmas, T3_ODOMETRY)
        for ceiling, curve in CELLS
        for i in range(runs)
    ]
    with TrialExecutor(workers, progress=progress) as ex:
        results = list(ex.imap(_t3_job, jobs, desc="Table III sweep"))
    rows = []
    for s, m, lik, frame in itertools.product(
        sigmas, T3_ODOMETRY, T3_LIKELIHOODS, T3_ACTION_FRAMES
    ):
        cells = {}
        for ceiling, curve in CELLS:
            res = [r[(lik, frame)] for r in results if r["key"] == (s, m, ceiling, curve)]
            conv = [r["converged"] for r in res if r["converged"] is not None]
            mean = float(np.mean(conv)) if conv else None
            cells[f"{ceiling}/{curve}"] = {
                "mean_updates_to_converge": mean,
                "std_updates_to_converge": float(np.std(conv, ddof=1)) if len(conv) > 1 else None,
                "converged_runs": len(conv),
                "paper": PAPER_TABLE_III[(ceiling, curve)],
                "deviation": deviation(mean, PAPER_TABLE_III[(ceiling, curve)]),
                "wrong_locks": int(sum(r["wrong"] for r in res)),
                "never_converged": int(sum(r["converged"] is None for r in res)),
                "runs_with_relocalization": int(sum(r["relocalizations"] > 0 for r in res)),
                "runs": len(res),
            }
        rows.append(
            {
                "pixel_sigma": s,
                "odometry_model": m,
                "likelihood": lik,
                "action_frame": frame,
                "cells": cells,
                "max_deviation": max(c["deviation"] for c in cells.values()),
                "wrong_locks": sum(c["wrong_locks"] for c in cells.values()),
                "runs_with_relocalization": sum(
                    c["runs_with_relocalization"] for c in cells.values()
                ),
            }
        )
    return rows


# ---- seed 004 Table 1 --------------------------------------------------------------------------
def seed004_reading(height: float, pitch_um: float, offset: float, noise: str) -> KaushikConfig:
    """The setup of one seed 004 reading: 2/3" sensor at `pitch_um` (resolution follows)."""
    return replace(
        KaushikConfig(),
        height=height,
        pixel_pitch_um=pitch_um,
        offset=offset,
        noise_reading=noise,
        width=int(round(1e3 * SENSOR_WIDTH_MM / pitch_um)),
        height_px=int(round(1e3 * SENSOR_HEIGHT_MM / pitch_um)),
    )


def genuine_p3p_errors(runs) -> np.ndarray:
    """Seed 004 Sec. III: per frame of `runs` (kaushik.simulate), P3P on the noisy pixels
    (batched over every frame) and the position error [m] of the candidate nearest the truth,
    for the frames with a candidate."""
    N, F = runs.t_wc.shape[:2]
    bearings, ok = runs.config.camera().pixel_to_bearing(runs.pixels.reshape(-1, 2))
    if not ok.all():
        raise ValueError(
            f"kaushik-p3p-error: {int((~ok).sum())} noisy pixels do not lift to bearings"
        )
    cands = solve_p3p(bearings.reshape(-1, 3, 3), np.broadcast_to(runs.leds, (N * F, 3, 3)))
    t = runs.t_wc.reshape(-1, 1, 3)
    d = np.where(cands.valid, np.linalg.norm(cands.t_wc - t, axis=2), np.inf)
    return d.min(axis=1)[cands.valid.any(axis=1)]


def _s4_job(job) -> dict:
    (height, pitch, offset, noise), runs, frames, seed = job
    base = seed004_reading(height, pitch, offset, noise)
    row = {"height": height, "pitch_um": pitch, "offset": offset, "noise_reading": noise}
    cells, worst = [], 0.0
    for i, (variance, focal) in enumerate(itertools.product(NOISE_VARIANCES, FOCALS_MM)):
        cfg = replace(
            base, focal_mm=focal, noise_variance=variance, runs=runs, frames=frames, seed=seed + i
        )
        paper = PAPER_SEED004_TABLE_1[(focal, variance)]
        try:
            e = genuine_p3p_errors(simulate(cfg))
        except ValueError as exc:  # an LED leaves the image: this reading cannot be the setup
            row.update(cells=None, max_deviation=np.inf, infeasible=str(exc))
            return row
        mean, std = float(e.mean()), float(e.std())
        dev = max(deviation(mean, paper[0]), deviation(std, paper[1]))
        worst = max(worst, dev)
        cells.append(
            {"focal_mm": focal, "noise_variance": variance, "mean": mean, "std": std, "dev": dev}
        )
    row.update(cells=cells, max_deviation=worst, infeasible=None)
    return row


def seed004_sweep(runs: int, frames: int, workers: int, progress: bool = True) -> list:
    grid = itertools.product(S4_HEIGHTS, S4_PITCHES_UM, S4_OFFSETS, S4_NOISE_READINGS)
    jobs = [(reading, runs, frames, 0) for reading in grid]
    with TrialExecutor(workers, progress=progress) as ex:
        return list(ex.imap(_s4_job, jobs, desc="seed 004 sweep"))


# ---- choice ------------------------------------------------------------------------------------
TIE = 0.01  # readings this close to the smallest largest deviation count as equally good


@dataclass(frozen=True)
class Choice:
    """The reading with the smallest largest deviation (of readings within TIE of it, the one
    listed first in the sweep: the sweeps list the stated value first, so a reading the numbers
    cannot tell apart from the stated one stays stated), whether it reproduces (all numbers
    within REPRODUCE_TOL) and how many readings do."""

    best: dict
    reproduces: bool
    reproducing_readings: int


def choose(rows: list[dict]) -> Choice:
    finite = [r for r in rows if np.isfinite(r["max_deviation"])]
    if not finite:
        raise ValueError("seed_baselines.choose: no feasible reading in the sweep")
    smallest = min(r["max_deviation"] for r in finite)
    best = next(r for r in finite if r["max_deviation"] <= smallest + TIE)
    n = sum(r["max_deviation"] <= REPRODUCE_TOL for r in finite)
    return Choice(best, best["max_deviation"] <= REPRODUCE_TOL, n)


def table1_config(best: dict, trials: int, workers: int) -> TableIConfig:
    """graphloc's Table I run under a Table I reading (the same noise as the seed baseline)."""
    return TableIConfig(
        trials=trials,
        workers=workers,
        pixel_sigma=best["pixel_sigma"],
        lateral_sigma=best["lateral_sigma"],
        orientation=best["orientation"],
    )


def table3_config(best: dict, runs: int, workers: int) -> TableIIIConfig:
    """Table III at a reading: its likelihood becomes belief Def. 1's or Def. 2's."""
    slot = "def1_likelihood" if best["likelihood"].startswith("inner") else "def2_likelihood"
    return TableIIIConfig(
        runs=runs,
        workers=workers,
        pixel_sigma=best["pixel_sigma"],
        odometry_model=best["odometry_model"],
        action_frame=best.get("action_frame", "solution"),
        **{slot: best["likelihood"]},
    )


def seed004_config(best: dict) -> KaushikConfig:
    return seed004_reading(best["height"], best["pitch_um"], best["offset"], best["noise_reading"])


def sweep_all(sizes: dict, workers: int, progress: bool = True) -> dict:
    """Every sweep at `sizes` (keys t1_trials, t3_runs, s4_runs, s4_frames); their choices."""
    t0 = time.perf_counter()
    jobs = [
        (s, lat, o, sizes["t1_trials"], 0)
        for s, lat, o in itertools.product(T1_PIXEL_SIGMAS, T1_LATERAL_SIGMAS, T1_ORIENTATIONS)
    ]
    with TrialExecutor(workers, progress=progress) as ex:
        t1 = list(ex.imap(_t1_job, jobs, desc="Table I sweep"))
    t3 = table3_sweep(sizes["t3_runs"], workers, progress=progress)
    s4 = seed004_sweep(sizes["s4_runs"], sizes["s4_frames"], workers, progress)
    return {
        "table1": {"rows": t1, "choice": asdict(choose(t1)), "paper": PAPER_TABLE_I},
        "table3": {"rows": t3, "choice": asdict(choose(t3))},
        "seed004": {"rows": s4, "choice": asdict(choose(s4))},
        "sweep_wall_time_s": time.perf_counter() - t0,
    }
