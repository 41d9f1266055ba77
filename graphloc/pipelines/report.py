"""Outputs of `graphloc smooth` / `graphloc online` (every field documented in docs/outputs.md):
per-robot TUM trajectories (estimate, dead reckoning, ground truth), metrics.json (per-robot
ATE / RPE via evo with the alignment stated, candidate-set decisions, what every table
contributed, skips, the effective configuration), decisions.csv and PNG plots."""

from __future__ import annotations

import csv
import json
from dataclasses import asdict
from pathlib import Path

import gtsam
import numpy as np
from evo.core.trajectory import PoseTrajectory3D

from graphloc.eval import ate_over_time, metrics_or_reason, write_tum
from graphloc.pipelines.team_graph import (
    STEP_LOG_COLUMNS,
    GraphConfig,
    TeamResult,
    build_graph,
    solve,
)
from graphloc.names import out_path, written_whole
from graphloc.plots import Series, plot_series, plot_trajectories
from graphloc.run import TeamRun
from graphloc.structured import dumps_json


def _trajectory(times: np.ndarray, rows: np.ndarray) -> PoseTrajectory3D:
    """(N,) times and (N,7) x y z qx qy qz qw rows -> evo trajectory (evo's quaternions are w
    first)."""
    ok = np.isfinite(rows).all(axis=1)
    q = rows[ok, 3:7]
    return PoseTrajectory3D(
        positions_xyz=rows[ok, :3],
        orientations_quat_wxyz=np.column_stack([q[:, 3], q[:, :3]]),
        timestamps=np.asarray(times, dtype=float)[ok],
    )


def groundtruth_rows(run: TeamRun, r: int) -> tuple[np.ndarray, np.ndarray] | None:
    gt = run.groundtruth[r]
    if gt is None or len(gt[0]) < 3:
        return None
    rows = np.array([np.r_[p.translation(), _quat(p)] for p in gt[1]])
    return np.asarray(gt[0]), rows


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


def _quat(p) -> np.ndarray:
    q = p.rotation().toQuaternion()
    return np.array([q.x(), q.y(), q.z(), q.w()])


def alignment(run: TeamRun, r: int) -> str:
    """How a robot's estimate is compared with its ground truth: planar robots of a run without
    absolute anchors other than their own start are SE(2)-aligned (as MRCLAM results are
    reported); every other robot is compared in the world frame the run defines ("none")."""
    return "se2" if run.robots[r].planar else "none"


def evaluate(result: TeamResult, run: TeamRun) -> dict:
    """Per-robot ATE/RPE of dead reckoning (the initial guess), the estimate and (online) the
    causal estimate; decisions; counts; latency; skips."""
    per_robot = {}
    for r, robot in enumerate(run.robots):
        ref = groundtruth_rows(run, r)
        times = result.node_times[r]
        if robot.static and run.groundtruth[r] is not None:
            per_robot[robot.name] = _static_error(result.estimate[r][0], run.groundtruth[r])
            continue
        if ref is None or not np.isfinite(result.estimate[r]).all(axis=1).any():
            per_robot[robot.name] = {"groundtruth": ref is not None, "poses": int(len(times))}
            continue
        reference = _trajectory(*ref)
        align = alignment(run, r)
        entry = {"groundtruth": True, "poses": int(len(times)), "alignment": align}
        tracks = {"dead_reckoning": result.dead_reckoning[r], result.mode: result.estimate[r]}
        if result.mode == "online":
            tracks["online_causal"] = result.causal[r]
        for label, rows in tracks.items():
            estimate = _trajectory(times, rows) if np.isfinite(rows).all(axis=1).any() else None
            entry[label], reason = metrics_or_reason(reference, estimate, align)
            if reason is not None:  # null metrics, and why
                entry.setdefault("not_evaluated", {})[label] = reason
        per_robot[robot.name] = entry
    decisions = result.decisions
    genuine = genuine_candidates(run, decisions)
    judged = [(d, g) for d, g in zip(decisions, genuine) if d.committed >= 0 and g >= 0]
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
    return {
        "run": run.name,
        "mode": result.mode,
        "robots": [r.name for r in run.robots],
        "duration_s": duration,
        "solve_wall_s": result.wall_s,
        "realtime_factor": duration / max(result.wall_s, 1e-12),
        "latency_ms": latency,
        "per_robot": per_robot,
        "decisions": {
            "candidate_sets": len(decisions),
            "committed": sum(d.committed >= 0 for d in decisions),
            "first_commit_time": first,
            "with_genuine_known": len(judged),
            "wrong": sum(g not in d.same_pose for d, g in judged),
            "genuine_merged": sum(g != d.committed and g in d.same_pose for d, g in judged),
        },
        "downweighted": result.downweighted,
        "counts": result.graph.counts,
        "tables": run.contributions,
        "skipped": result.graph.skips.as_dict(),
        "notes": run.notes.as_dict(),
        "partial": bool(result.partial),
        "steps_done": int(result.steps_done),
        "steps_total": len(result.graph.steps),
        "lag_s": result.lag,
        "batch_start": result.batch_start or None,
        "dropped_across_lag": dict(result.dropped),
        "latency_trend": latency_trend(result),
    }


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
    trajectory = _trajectory(times, rows)
    return write_tum(path, trajectory.timestamps, np.array(trajectory.poses_se3))


def write_outputs(result: TeamResult, run: TeamRun, metrics: dict, out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for r, robot in enumerate(run.robots):
        times = result.node_times[r]
        for label, rows in (
            (result.mode, result.estimate[r]),
            ("dead_reckoning", result.dead_reckoning[r]),
        ):
            if np.isfinite(rows).all(axis=1).any():
                written.append(_write_rows(out_path(out, f"{robot.name}_{label}.tum"), times, rows))
        ref = groundtruth_rows(run, r)
        if ref is not None:
            written.append(_write_rows(out_path(out, f"{robot.name}_groundtruth.tum"), *ref))
    path = out_path(out, "decisions.csv")
    decisions = result.decisions
    with written_whole(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(
            [
                "time",
                "robot",
                "target",
                "candidates",
                "committed",
                "probability",
                "genuine",
                "correct",
                "x",
                "y",
                "z",
                "qx",
                "qy",
                "qz",
                "qw",
            ]
        )
        for d, g in zip(decisions, genuine_candidates(run, decisions)):
            correct = "" if d.committed < 0 or g < 0 else int(g in d.same_pose)
            w.writerow(
                [
                    f"{d.time:.6f}",
                    run.robots[d.robot].name,
                    run.robots[d.target].name,
                    len(d.candidates_xyz),
                    d.committed,
                    f"{d.probability:.6g}",
                    g,
                    correct,
                    *(f"{v:.9g}" for v in d.pose),
                ]
            )
    written.append(path)
    if result.mode == "online":
        path = out_path(out, "latency.csv")
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
        written.append(path)
    written.append(out_path(out, "metrics.json"))
    with written_whole(written[-1]) as tmp:
        tmp.write_text(dumps_json(metrics, indent=2, default=str) + "\n")
    written += _plots(result, run, out)
    return written


def _plots(result: TeamResult, run: TeamRun, out: Path) -> list[Path]:
    import matplotlib

    cmap = matplotlib.colormaps["tab10"]
    est, ref, err = [], [], []
    for r, robot in enumerate(run.robots):
        rows = result.estimate[r]
        if robot.static or not np.isfinite(rows).all(axis=1).any():
            continue
        est.append(Series(f"{robot.name} {result.mode}", rows[:, :2], color=cmap(r % 10)))
        g = groundtruth_rows(run, r)
        if g is not None:
            ref.append(
                Series(
                    "ground truth" if not ref else "_nolegend_",
                    g[1][:, :2],
                    style="--",
                    color="0.4",
                )
            )
            try:
                t, e = ate_over_time(
                    _trajectory(*g),
                    _trajectory(result.node_times[r], rows),
                    align=alignment(run, r),
                )
                err.append(
                    Series(f"{robot.name} {result.mode}", t - run.start_time, e, color=cmap(r % 10))
                )
            except ValueError:
                pass
    chosen = np.array([d.pose[:2] for d in result.decisions if d.committed >= 0]).reshape(-1, 2)
    if len(chosen):
        est.append(Series("committed candidates", chosen, style=".", color="tab:green"))
    rejected = _rejected_candidates(run, result)
    if len(rejected):
        est.append(Series("rejected candidates", rejected, style="x", color="tab:red"))
    statics = [r for r in run.robots if r.static and r.initial_pose is not None]
    points = np.array(
        [
            r.initial_pose.transformFrom(m)[:2]
            for r in statics
            for m in (r.markers if r.markers is not None else [np.zeros(3)])
        ]
    )
    if run.landmarks_known and len(run.landmark_xyz):
        points = np.vstack([points.reshape(-1, 2), run.landmark_xyz[:, :2]])
    written = [
        plot_trajectories(
            out_path(out, "trajectories.png"),
            est,
            ref,
            points if len(points) else None,
            title=f"{run.name}: {result.mode} (top view)",
            point_label="landmarks / markers",
        )
    ]
    if err:
        written.append(
            plot_series(
                out_path(out, "error_over_time.png"),
                err,
                "time since start [s]",
                "position error [m]",
                f"{run.name}: error over time",
                logy=True,
            )
        )
    csv_path = out_path(out, "latency.csv")
    if result.mode == "online" and csv_path.exists():
        table = np.genfromtxt(csv_path, delimiter=",", names=True).reshape(-1)
        if len(table):
            lag = f"lag {result.lag:g} s" if result.lag else "full smoothing"
            series = [
                Series("wall", table["step"], table["latency_s"] * 1e3),
                Series("CPU", table["step"], table["cpu_s"] * 1e3, style="."),
            ]
            title = f"{run.name}: online latency ({lag}, latency.csv)"
            written.append(
                plot_series(
                    out_path(out, "latency.png"),
                    series,
                    "step",
                    "latency per step [ms]",
                    title,
                    logy=True,
                )
            )
    return written


def _rejected_candidates(run: TeamRun, result: TeamResult) -> np.ndarray:
    """World xy of every candidate the tracker did not commit (body position of the observer)."""
    out = [
        xyz[:2]
        for d in result.decisions
        for j, xyz in enumerate(d.candidates_xyz)
        if j != d.committed
    ]
    return np.array(out).reshape(-1, 2)


def genuine_candidates(run: TeamRun, decisions: list, max_time_diff: float = 0.02) -> list[int]:
    """Per decision, the genuine candidate: the one nearest the observer's true position (ground
    truth within max_time_diff of the set's time), or -1 where the run has no ground truth there."""
    out = []
    for d in decisions:
        gt = run.groundtruth[d.robot]
        if gt is None or not len(gt[0]):
            out.append(-1)
            continue
        if (
            d.relative is not None
        ):  # max-mixture route: the candidate nearest the true relative pose
            out.append(_genuine_relative(run, d, max_time_diff))
            continue
        i = int(np.argmin(np.abs(gt[0] - d.time)))
        if abs(gt[0][i] - d.time) > max_time_diff or not len(d.candidates_xyz):
            out.append(-1)
            continue
        out.append(
            int(np.argmin(np.linalg.norm(d.candidates_xyz - gt[1][i].translation(), axis=1)))
        )
    return out


def _genuine_relative(run: TeamRun, d, max_time_diff: float) -> int:
    """The candidate (observer body_T_target, `Decision.relative`) nearest the true relative
    pose (rotation angle [rad] plus translation [m] over 0.1 m), -1 without ground truth."""
    rel = []
    for r in (d.robot, d.target):
        gt = run.groundtruth[r]
        if gt is None or not len(gt[0]):
            return -1
        i = int(np.argmin(np.abs(gt[0] - d.time)))
        if abs(gt[0][i] - d.time) > max_time_diff:
            return -1
        rel.append(gt[1][i])
    truth = rel[0].between(rel[1])
    cost = []
    for T in d.relative:
        e = gtsam.Pose3.Logmap(truth.between(gtsam.Pose3(T)))
        cost.append(np.linalg.norm(e[:3]) + np.linalg.norm(e[3:]) / 0.1)
    return int(np.argmin(cost))


def run_and_report(
    run: TeamRun,
    out: Path,
    mode: str,
    config: GraphConfig,
    progress: bool = True,
    effective: dict | None = None,
) -> dict:
    """Build the graph, solve it (batch or online), evaluate, write outputs; returns the metrics."""
    result = solve(build_graph(run, config, progress=progress), mode=mode, progress=progress)
    metrics = evaluate(result, run)
    metrics["config"] = json.loads(dumps_json(asdict(config), default=str))
    if effective:
        metrics["options"] = effective
    write_outputs(result, run, metrics, Path(out))
    return metrics
