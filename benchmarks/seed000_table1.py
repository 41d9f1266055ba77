"""Seed 000 (000_05137a0a9c449be3.txt) Table I (Sec. VI-A), paper | seed baseline (ours) |
graphloc on the same trials: ground triangle from graphloc.vision.mutual on noisy 512x512 omni
pixels (C1 is the reference; `graphloc.datasets.feng_deterministic.ground_triangle`), camera C
from P3P + the straight-line test (seed, Sec. IV; `benchmarks.baselines.straight_line`) vs
graphloc through the front door: each trial written as a log of its measurements and solved
as `graphloc smooth` does (`benchmarks.front_door.table_i_trial`: C2, C3 placed by
mutual bearings, C by P3P, one graph). Tables II, III, the plots and the command line are
`benchmarks.seed000`.
"""

from __future__ import annotations

import time
from dataclasses import asdict, fields, replace

import numpy as np

from benchmarks.baselines.straight_line import localize_by_straight_line
from graphloc.datasets.feng_deterministic import (
    TableIConfig,
    ground_triangle,
    simulate_straight_line_trials,
    Seed000Config,
)
from benchmarks.trials import TrialExecutor
from graphloc.geometry.p3p import MAX_CANDIDATES
from benchmarks.front_door import table_i_trial

PAPER_TABLE_I = {
    "success": 997,
    "trials": 1000,
    "C2": (1.7e-4, 6.1e-5),
    "C3": (1.6e-4, 5.1e-5),
    "C": (5.7e-4, 1.3e-4),
}


def trial_rows(record, rows: np.ndarray):
    """The same frozen dataclass with every per-trial array field restricted to `rows`."""
    n = len(record.ground) if hasattr(record, "ground") else len(record.status)

    def per_trial(name: str) -> bool:
        value = getattr(record, name)
        return isinstance(value, np.ndarray) and len(value) == n and value.ndim >= 1 and name != "K"

    return replace(
        record,
        **{f.name: getattr(record, f.name)[rows] for f in fields(record) if per_trial(f.name)},
    )


def run_front_door(
    trials, tri, rows: np.ndarray, config: TableIConfig, step_sigma: float, progress: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """graphloc through the front door (`front_door.table_i_trial`: the trial as a log, the
    team graph, batch) for the trials `rows` (others stay NaN), on `config.workers` processes.
    Returns climber centres (T,3,3), ground positions (T,3,3), graph errors (T,)."""
    T = len(trials.ground)
    positions, ground = np.full((T, 3, 3), np.nan), np.full((T, 3, 3), np.nan)
    errors = np.full(T, np.inf)
    jobs = [
        (trial_rows(trials, [i]), trial_rows(tri, [i]), config.pixel_sigma, step_sigma)
        for i in rows
    ]
    with TrialExecutor(config.workers, progress=progress) as ex:
        results = ex.imap(table_i_trial, jobs, desc="Table I through the front door")
        for i, (pos, g, err, _) in zip(rows, results):
            positions[i], ground[i], errors[i] = pos, g, err
    return positions, ground, errors


def _classify_failures(ok: np.ndarray, ground_ok: np.ndarray, graph_error: np.ndarray) -> dict:
    """graphloc's failed trials: ground triangle rejected by the front-end; a fit as good as
    the successes' (graph error below their 99th percentile: the data cannot tell -- the P3P
    singularity the seed blames for its 3 failures); or a poor fit (a wrong basin)."""
    fail = ground_ok & ~ok
    p99 = np.percentile(graph_error[ok], 99) if ok.any() else np.inf
    return {
        "ground_triangle_rejected": int((~ground_ok).sum()),
        "consistent_fit_ill_conditioned": int((fail & (graph_error <= p99)).sum()),
        "poor_fit_wrong_basin": int((fail & np.isfinite(graph_error) & (graph_error > p99)).sum()),
        "optimizer_failed": int((fail & ~np.isfinite(graph_error)).sum()),
        "success_graph_error_p99": float(p99),
    }


def _rel_stats(errors: np.ndarray, scale: float) -> dict:
    e = errors[np.isfinite(errors)]
    if e.size == 0:
        return {"mean": None, "std": None, "abs_mean_m": None, "abs_median_m": None, "n": 0}
    return {
        "mean": float(e.mean() / scale),
        "std": float(e.std() / scale),
        "abs_mean_m": float(e.mean()),
        "abs_median_m": float(np.median(e)),
        "n": int(e.size),
    }


def table_i(config: TableIConfig = TableIConfig(), progress: bool = True) -> dict:
    """Seed 000 Table I on `config.trials` trials (see the module docstring). Returns success
    counts and relative errors (mean, std over successful trials) of C2, C3 and C for the seed
    baseline and graphloc, the paper's numbers, timings and the failure breakdown."""
    t_start = time.perf_counter()
    sim = Seed000Config(
        pixel_sigma=config.pixel_sigma,
        lateral_sigma=config.lateral_sigma,
        orientation=config.orientation,
    )
    # formations where some robot stays outside another's omni field of view whatever the
    # orientation are redrawn (as feng_deterministic redraws trials where C cannot see them)
    pool = simulate_straight_line_trials(
        int(1.1 * config.trials) + 10, seed=config.seed, config=sim
    )
    tri = ground_triangle(pool.ground, config, np.random.default_rng([config.seed, 1]))
    rows = np.flatnonzero(tri.visible)[: config.trials]
    if rows.size < config.trials:
        raise ValueError(
            f"seed000 Table I: only {rows.size} of {len(pool.ground)} formations "
            f"are mutually visible with omni_max_polar={config.omni_max_polar:.3f}"
        )
    unobservable = int((~tri.visible[: rows[-1] + 1]).sum())
    trials, tri = trial_rows(pool, rows), trial_rows(tri, rows)
    ground_ok = np.isfinite(tri.estimated).all(axis=(1, 2))
    err_ground = np.linalg.norm(tri.estimated - trials.ground, axis=2)  # (T,3), NaN: rejected
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
    cand_t[ok_rows] = choice.candidates.t_wc.reshape(-1, 3, MAX_CANDIDATES, 3)
    cand_valid[ok_rows] = choice.candidates.valid.reshape(-1, 3, MAX_CANDIDATES)

    # graphloc: each trial as a log through the front door (open_run -> team graph -> batch)
    t0 = time.perf_counter()
    joint_pos, joint_ground, joint_graph_error = run_front_door(
        trials, tri, ok_rows, config, 3 * sim.step_mean, progress
    )
    joint_time = time.perf_counter() - t0

    truth_to_candidates = np.where(
        cand_valid, np.linalg.norm(cand_t - trials.positions[:, :, None, :], axis=3), np.inf
    )
    nearest_pseudo = np.sort(truth_to_candidates, axis=2)[:, :, 1]  # (T,3) closest wrong solution

    def success(pos: np.ndarray) -> np.ndarray:
        """The paper's "correct result": in all three snapshots the estimate is closer to the
        truth than any pseudo P3P solution is. For a method that picks candidates (the seed)
        this is exactly "picked the genuine one"; a refined estimate may be better than the
        genuine candidate itself."""
        err = np.linalg.norm(pos - trials.positions, axis=2)
        return ground_ok & (np.nan_to_num(err, nan=np.inf) < nearest_pseudo).all(axis=1)

    def outcome(
        pos: np.ndarray, ground_est: np.ndarray, ok: np.ndarray, common: np.ndarray
    ) -> dict:
        err_ground = np.linalg.norm(ground_est - trials.ground, axis=2)
        err = np.linalg.norm(pos - trials.positions, axis=2)
        within = ground_ok & (np.nan_to_num(err, nan=np.inf).max(axis=1) < config.success_tol)

        def stats(mask):
            return {
                "C2": _rel_stats(err_ground[mask, 1], config.scale),
                "C3": _rel_stats(err_ground[mask, 2], config.scale),
                "C": _rel_stats(err[mask].ravel(), config.scale),
            }

        return {
            "success": int(ok.sum()),
            "within_tol": int(within.sum()),
            **stats(ok),
            "common_trials": stats(common),
        }

    seed_ok, joint_ok = success(seed_pos), success(joint_pos)
    common = seed_ok & joint_ok

    # the genuine P3P candidate with the *true* ground positions: the front-end's noise floor
    floor = localize_by_straight_line(trials.pixels, trials.K, trials.ground)
    floor_t = floor.candidates.t_wc.reshape(-1, 3, MAX_CANDIDATES, 3)
    floor_d = np.where(
        floor.candidates.valid.reshape(-1, 3, MAX_CANDIDATES),
        np.linalg.norm(floor_t - trials.positions[:, :, None, :], axis=3),
        np.inf,
    ).min(axis=2)

    def finite_median(x: np.ndarray) -> float:
        return float(np.nanmedian(np.where(np.isfinite(x), x, np.nan)))

    return {
        "table": "seed000-table1",
        "config": asdict(config),
        "trials": config.trials,
        "paper": PAPER_TABLE_I,
        "common_successes": int(common.sum()),
        "graphloc_failures": _classify_failures(joint_ok, ground_ok, joint_graph_error),
        "seed_baseline": {
            **outcome(seed_pos, tri.estimated, seed_ok, common),
            "line_error_median_m": finite_median(choice.error),
            "second_line_error_median_m": finite_median(choice.second_error),
        },
        "graphloc": {
            **outcome(joint_pos, joint_ground, joint_ok, common),
            "graph_error_median": float(
                np.median(joint_graph_error[np.isfinite(joint_graph_error)])
            ),
        },
        "failures": {
            "ground_triangle_rejected": int((~ground_ok).sum()),
            "ground_status": {
                str(s): int(n) for s, n in zip(*np.unique(tri.status, return_counts=True))
            },
            "ground_orientation_redraws": tri.redrawn,
            "formations_redrawn_not_mutually_visible": unobservable,
            "camera_trials_redrawn": trials.redrawn,
        },
        "evidence": {
            "genuine_p3p_error_true_ground_median_m": float(np.median(floor_d)),
            "genuine_p3p_error_true_ground_p90_m": float(np.percentile(floor_d, 90)),
            "ground_error_median_m": float(np.nanmedian(err_ground[:, 1:])),
        },
        "timing": {
            "seed_batched_s": seed_time,
            "graphloc_s": joint_time,
            "total_s": time.perf_counter() - t_start,
        },
    }
