"""The seeds' tables from logs, through the front door: a scenario's `graphloc simulate` log
read by `graphloc.datasets.open_run` and solved by `graphloc.pipelines.team_graph` (what
`graphloc smooth` / `online` run), with the per-set decisions and the per-frame errors the
tables need. `simulated_run` writes and reads one log; `table_i_trial` is graphloc's
estimate of one seed 000 Table I trial (Sec. VI-A); `feng_table_iii_run` is graphloc's column
of seed 000 Table III (Sec. VI-B) on one run, in the statistics
`benchmarks.hypotheses.summarize` pools."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from graphloc.datasets import open_run
from graphloc.datasets.formation_log import GROUND, write_table_i_trial
from graphloc.datasets.scenarios import generate
from benchmarks.locks import lock_statistics
from graphloc.pipelines.judge import genuine_candidates
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.runner.team_run import team_graph
from graphloc.run import TeamRun


def simulated_run(scenario: str, seed: int, overrides: dict) -> TeamRun:
    """`graphloc simulate SCENARIO --seed SEED` with `overrides` (config fields) into a
    temporary directory, read back by `open_run`."""
    with tempfile.TemporaryDirectory() as tmp:
        generate(scenario, Path(tmp) / "run", seed, overrides)
        return open_run(Path(tmp) / "run")


def truth_at(run: TeamRun, r: int, times: np.ndarray) -> np.ndarray:
    """Robot r's true positions (N,3) at `times` (the nearest ground-truth stamp)."""
    gt_t, gt_p = run.groundtruth[r]
    idx = np.clip(np.searchsorted(gt_t, np.asarray(times) - 1e-9), 0, len(gt_t) - 1)
    return np.array([gt_p[i].translation() for i in idx]).reshape(-1, 3)


def feng_table_iii_run(overrides: dict, seed: int, wrong_distance: float) -> dict:
    """One seed 000 Sec. VI-B run (`feng-probabilistic` with `overrides`) through the front
    door. Frame k = the k-th update of the run (update 1 = the first odometry step). A decided
    set is correct when its candidate is the genuine one (nearest the truth) or the same pose
    as it (`team_graph.candidates.same_pose`), or its pose is within `wrong_distance` of the
    truth. converged / correct_lock: frame of the first decided / first correct decided set;
    relocalizations: decided sets that follow an undecided one after the first decision;
    rmse_locked: the decided poses; rmse_locked_batch / _online: the batch and online
    estimates on the frames from the first decision on; mean_latency_ms: per online step."""
    run = simulated_run("feng-probabilistic", seed, overrides)
    r = run.index("climber")
    graph = team_graph(run, GraphConfig())
    results = {mode: solve(graph, mode) for mode in ("batch", "online")}
    decisions = graph.decisions
    times = graph.node_times[r]
    truth = truth_at(run, r, times)
    genuine = genuine_candidates(run, decisions)
    frames, previous, first = [], None, None
    for d, g in zip(decisions, genuine):
        k = int(np.argmin(np.abs(times - d.time)))
        decided = d.committed >= 0
        relocalized = decided and previous is False and first is not None
        previous = decided
        if not decided:
            frames.append((k, False, False, 0.0, relocalized))
            continue
        first = k if first is None else first
        err2 = float(np.sum((d.pose[:3] - truth[k]) ** 2))
        frames.append((k, True, g in d.same_pose or err2 < wrong_distance**2, err2, relocalized))
    out = {
        **lock_statistics(frames),
        "rmse_locked_batch": None,
        "rmse_locked_online": None,
        "resolved_frames": 0,
        "frames": len(times),
        "mean_latency_ms": 1e3 * float(np.mean(results["online"].latencies))
        if len(results["online"].latencies)
        else 0.0,
    }
    converged = out["converged"]
    if converged is not None:
        after = np.arange(len(times)) >= converged
        for mode, res in results.items():
            err = np.linalg.norm(res.estimate[r][after, :3] - truth[after], axis=1)
            out[f"rmse_locked_{mode}"] = float(np.sqrt(np.mean(err**2)))
        out["resolved_frames"] = int(after.sum())
    return out


def table_i_trial(job: tuple) -> tuple[np.ndarray, np.ndarray, float, dict]:
    """graphloc's estimate of one seed 000 Table I trial through the front door: the trial
    written as a log of measurements (`graphloc.datasets.formation_log`: mutual bearings, the
    known |T_12|, the climber's bearings and straight move), read by `open_run`, solved in
    batch by the team graph (C2, C3 placed by mutual bearings, the climber by P3P with every
    candidate as a start). job: (trials, triangle) restricted to the one trial, pixel_sigma,
    step_sigma. Returns the climber's three positions (3,3), the ground robots' positions
    (3,3) (NaN where left out), the graph error (inf without a placed climber) and the CPU
    seconds (time.process_time: this process, all its threads) of each phase: "write" (the
    log written), "read" (open_run), "build" (team_graph), "solve" (solve, batch)."""
    trials, triangle, pixel_sigma, step_sigma = job
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.process_time()
        write_table_i_trial(
            trials, triangle, 0, pixel_sigma, step_sigma, "seed000-table1", Path(tmp) / "run"
        )
        t1 = time.process_time()
        run = open_run(Path(tmp) / "run")
        t2 = time.process_time()
        graph = team_graph(run, GraphConfig())
        t3 = time.process_time()
        result = solve(graph, "batch")
        t4 = time.process_time()
    seconds = {"write": t1 - t0, "read": t2 - t1, "build": t3 - t2, "solve": t4 - t3}
    names = [r.name for r in run.robots]
    climber = result.estimate[names.index("climber")][:, :3]
    ground = np.array([result.estimate[names.index(g)][0, :3] for g in GROUND])
    placed = np.isfinite(climber).all() and len(climber) == 3
    if not placed:
        return np.full((3, 3), np.nan), ground, float("inf"), seconds
    return climber, ground, float(result.error), seconds
