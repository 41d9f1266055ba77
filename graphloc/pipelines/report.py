"""Outputs of `graphloc smooth` / `online` (docs/outputs.md): TUM trajectories, metrics.json,
decisions.csv and PNG plots."""

from __future__ import annotations

import contextlib
import csv
from pathlib import Path

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.eval import trajectory_metrics, write_tum
from graphloc.exitcodes import OutputDropped
from graphloc.pipelines.groundtruth import alignment, groundtruth_written, groundtruths, paired
from graphloc.names import out_path, written_whole
from graphloc.pipelines.judge import judge_decisions
from graphloc.pipelines.report_plots import plot_jobs
from graphloc.pipelines.team_graph import STEP_LOG_COLUMNS, TeamResult
from graphloc.pipelines.team_graph.verdict import candidate_streams, judge
from graphloc.run import TeamRun
from graphloc.structured import dumps_json


def _static_error(row: np.ndarray, gt) -> dict:
    """A static robot's one pose against its ground truth (the first stamp): position error
    [m] and rotation error [deg] in the run's world frame (null when the robot was left out)."""
    entry = {"groundtruth": True, "poses": 1, "alignment": "none"}
    if not np.isfinite(row).all():
        return {**entry, "position_error_m": None, "rotation_error_deg": None}
    true = gt[1][0]
    est = gtsam.Pose3(gtsam.Rot3.Quaternion(row[6], row[3], row[4], row[5]), row[:3])
    return {
        **entry,
        "position_error_m": float(np.linalg.norm(row[:3] - true.translation())),
        "rotation_error_deg": float(
            np.degrees(np.linalg.norm(gtsam.Rot3.Logmap(true.rotation().between(est.rotation()))))
        ),
    }


def evaluate(
    result: TeamResult,
    run: TeamRun,
    truth: list | None = None,
    stop=None,
    align: str | None = None,
    cpu_s: float | None = None,
) -> dict:
    """Per-robot ATE/RPE of dead reckoning, the estimate and (online) the causal estimate, decisions
    judged by the truth, the consistency verdict, counts, latency and skips. Once `stop()` is
    True, the remaining trajectories are not evaluated ("evaluated" False)."""
    truth = groundtruths(run) if truth is None else truth
    per_robot = {}
    evaluated = True
    aligns = [alignment(run, r, align) for r in range(len(run.robots))]
    for r, robot in enumerate(run.robots):
        ref = truth[r]
        times = result.node_times[r]
        if robot.static and run.groundtruth[r] is not None:
            per_robot[robot.name] = _static_error(result.estimate[r][0], run.groundtruth[r])
            continue
        if ref is None or not np.isfinite(result.estimate[r]).all(axis=1).any():
            per_robot[robot.name] = {"groundtruth": ref is not None, "poses": int(len(times))}
            continue
        entry = {"groundtruth": True, "poses": int(len(times)), "alignment": aligns[r]}
        tracks = {"dead_reckoning": result.dead_reckoning[r], result.mode: result.estimate[r]}
        if result.mode == "online":
            tracks["online_causal"] = result.causal[r]
        for label, rows in tracks.items():
            if stop is not None and stop():
                evaluated = False
                break
            entry[label], reason = _metrics(ref, times, rows, aligns[r])
            if reason is not None:  # null metrics, and why
                entry.setdefault("not_evaluated", {})[label] = reason
        per_robot[robot.name] = entry
    decisions = result.decisions
    genuine, correct = judge_decisions(run, decisions)
    judged = [
        (d, g, c)
        for d, g, c in zip(decisions, genuine, correct)
        if d.committed >= 0 and c is not None
    ]
    lat = result.latencies
    latency = (
        {
            "mean": float(lat.mean() * 1e3),
            "p50": float(np.percentile(lat, 50) * 1e3),
            "p95": float(np.percentile(lat, 95) * 1e3),
            "max": float(lat.max() * 1e3),
        }
        if result.mode == "online" and len(lat)
        else None
    )
    first = next((d.time for d in decisions if d.committed >= 0), None)
    duration = float(
        max((t[-1] for t in result.node_times if len(t)), default=run.start_time) - run.start_time
    )
    names = [r.name for r in run.robots]
    streams = candidate_streams(decisions, names)
    unplaced = [
        robot.name
        for r, robot in enumerate(run.robots)
        if len(result.node_times[r]) and not np.isfinite(result.estimate[r]).all(axis=1).any()
    ]
    skipped = result.graph.skips.as_dict()
    verdict = judge(result.factor_stats, streams, unplaced, skipped, robot_stats=result.robot_stats)
    if result.partial:  # a stopped solve is not judged
        verdict.update(consistent=None, failures=[], warnings=[])
    return {
        "run": run.name,
        "mode": result.mode,
        "consistent": verdict["consistent"],
        "consistency": verdict,
        "graph_error": result.error,
        "factors": result.factor_stats,
        "factors_by_robot": result.robot_stats,
        "candidate_streams": streams,
        "robots": [r.name for r in run.robots],
        "duration_s": duration,
        "solve_wall_s": result.wall_s,
        "cpu_s": cpu_s,
        "realtime_factor": duration / max(result.wall_s if cpu_s is None else cpu_s, 1e-12),
        "latency_ms": latency,
        "evaluated": evaluated,
        "per_robot": per_robot,
        "decisions": {
            "candidate_sets": len(decisions),
            "committed": sum(d.committed >= 0 for d in decisions),
            "first_commit_time": first,
            "with_genuine_known": len(judged),
            "wrong": sum(not c for _, _, c in judged),
            "genuine_merged": sum(c and g != d.committed for d, g, c in judged),
            "inconsistent": sum(d.status == "inconsistent" for d in decisions),
        },
        "downweighted": result.downweighted,
        "counts": result.graph.counts,
        "tables": run.contributions,
        "skipped": skipped,
        "notes": run.notes.as_dict(),
        "partial": bool(result.partial),
        "steps_done": int(result.steps_done),
        "steps_total": len(result.graph.steps),
        "lag_s": result.lag,
        "batch_start": result.batch_start or None,
        "solver_note": result.solver_note or None,
        "dropped_across_lag": dict(result.dropped),
        "latency_trend": latency_trend(result),
    }


def _metrics(truth, times, rows, align: str) -> tuple[dict | None, str | None]:
    """`trajectory_metrics` of one track against its ground truth and None, or None and why there
    are none (fewer than 3 poses, too few near ground-truth stamps, a robot that never moved)."""
    n = int(np.isfinite(rows).all(axis=1).sum())
    if n < 3:
        return None, f"{n} poses, 3 needed"
    try:
        pairs = paired(truth, times, rows)
        return trajectory_metrics(*pairs, align=align, associated=True).as_dict(), None
    except ValueError as exc:
        return None, str(exc)


def latency_trend(result: TeamResult) -> dict | None:
    """Online: p95 of the per-step latency and CPU time [ms] over the first and the last tenth
    of the steps, their ratio, the slowest step's CPU time, and the variables the solver holds
    at the end (bounded with a fixed lag)."""
    log = result.step_log
    if result.mode != "online" or len(log) < 10:
        return None
    n = len(log) // 10
    out = {}
    for name, col in (("latency", 2), ("cpu", 3)):
        first, last = (float(np.percentile(x, 95) * 1e3) for x in (log[:n, col], log[-n:, col]))
        out[f"{name}_p95_first10_ms"], out[f"{name}_p95_last10_ms"] = first, last
        out[f"{name}_p95_last_over_first"] = last / max(first, 1e-12)
    out["cpu_max_ms"] = float(log[:, 3].max() * 1e3)
    out["variables_end"] = int(log[-1, 5])
    out["variables_max"] = int(log[:, 5].max())
    return out


def _write_rows(path: Path, times: np.ndarray, rows: np.ndarray) -> Path:
    """(N,) times and (N,7) x y z qx qy qz qw rows (NaN rows skipped) through the one TUM writer."""
    ok = np.isfinite(rows).all(axis=1)
    return write_tum(path, np.asarray(times, dtype=float)[ok], rows[ok])


def write_outputs(
    result: TeamResult,
    run: TeamRun,
    metrics: dict,
    out: Path,
    groundtruth_rate: str = "estimate",
    progress: bool = False,
    truth: list | None = None,
    stop=None,
    align: str | None = None,
) -> list[Path]:
    """Every output file of docs/outputs.md into `out`, metrics.json last. Once `stop()` is True,
    what is derived and not written yet (dead reckoning, ground truth, PNGs) is left out and
    listed in metrics.json's "skipped_outputs"; a PNG being drawn is dropped (`OutputDropped`)."""
    truth = groundtruths(run) if truth is None else truth
    out.mkdir(parents=True, exist_ok=True)
    jobs = []  # (file name, writer[, "derived": left out once stopped; "plot": that, droppable])
    for r, robot in enumerate(run.robots):
        times = result.node_times[r]
        if np.isfinite(result.estimate[r]).all(axis=1).any():
            path = out_path(out, f"{robot.name}_{result.mode}.tum")
            rows = result.estimate[r]
            jobs.append((path.name, lambda p=path, t=times, x=rows: _write_rows(p, t, x)))
        if np.isfinite(result.dead_reckoning[r]).all(axis=1).any():
            path = out_path(out, f"{robot.name}_dead_reckoning.tum")
            rows = result.dead_reckoning[r]
            job = lambda p=path, t=times, x=rows: _write_rows(p, t, x)  # noqa: E731
            jobs.append((path.name, job, "derived"))
        if truth[r] is not None:
            path = out_path(out, f"{robot.name}_groundtruth.tum")
            g = truth[r]
            job = lambda p=path, g=g, t=times: _write_rows(  # noqa: E731
                p, *groundtruth_written(g, t, groundtruth_rate)
            )
            jobs.append((path.name, job, "derived"))
    decisions = out_path(out, "decisions.csv")
    jobs.append(("decisions.csv", lambda: _write_decisions(decisions, result, run)))
    if result.mode == "online":
        latency = out_path(out, "latency.csv")
        jobs.append(("latency.csv", lambda: _write_latency(latency, result)))
    plots = plot_jobs(result, run, out, truth, groundtruth_rate, align)
    stopped = result.partial or not metrics.get("evaluated", True)
    jobs += [(name, job, "plot") for name, job in plots]
    written, skipped = [], [] if metrics.get("evaluated", True) else ["ATE / RPE"]
    bar = tqdm(
        jobs + [("metrics.json", None)],
        desc="writing outputs",
        unit="file",
        disable=not progress,
        leave=False,
    )
    for name, job, *kind in bar:
        bar.set_postfix_str(name)
        if job is None:  # metrics.json, last: it says what was left out
            metrics["skipped_outputs"] = skipped
            written.append(write_metrics(out, metrics))
        elif kind and (stop is not None and stop()):  # a signal: derived outputs left out
            skipped.append(name)
        elif kind == ["plot"] and stopped:  # no figures of a stopped solve
            skipped.append(name)
        elif kind == ["plot"]:  # a figure: a signal while it is drawn drops it (`OutputDropped`)
            try:
                with getattr(stop, "droppable", contextlib.nullcontext)():
                    path = job()
            except OutputDropped:
                skipped.append(name)
                continue
            if path is not None:
                written.append(path)
        elif (path := job()) is not None:
            written.append(path)
    bar.close()
    return written


def write_metrics(out: Path, metrics: dict) -> Path:
    """metrics.json into `out`, whole (`names.written_whole`)."""
    path = out_path(out, "metrics.json")
    with written_whole(path) as tmp:
        tmp.write_text(dumps_json(metrics, indent=2, default=str) + "\n")
    return path


DECISION_COLUMNS = (
    "time robot target candidates status committed probability genuine correct x y z qx qy qz qw"
).split()


def _write_decisions(path: Path, result: TeamResult, run: TeamRun) -> Path:
    decisions = result.decisions
    with written_whole(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(DECISION_COLUMNS)
        for d, g, c in zip(decisions, *judge_decisions(run, decisions)):
            correct = "" if d.committed < 0 or c is None else int(c)
            w.writerow(
                [
                    f"{d.time:.6f}",
                    run.robots[d.robot].name,
                    run.robots[d.target].name,
                    len(d.candidates_xyz),
                    d.status,
                    d.committed,
                    f"{d.probability:.6g}",
                    g,
                    correct,
                    *(f"{v:.9g}" for v in d.pose),
                ]
            )
    return path


def _write_latency(path: Path, result: TeamResult) -> Path:
    with written_whole(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(STEP_LOG_COLUMNS)
        for row in result.step_log:
            w.writerow(
                [
                    int(row[0]),
                    f"{row[1]:.6f}",
                    f"{row[2]:.9f}",
                    f"{row[3]:.9f}",
                    int(row[4]),
                    int(row[5]),
                ]
            )
    return path
