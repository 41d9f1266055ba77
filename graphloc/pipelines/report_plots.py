"""The PNG plots of `graphloc smooth` / `online`, one job per figure (`plot_jobs`)."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np

from graphloc.eval import ate_over_time
from graphloc.pipelines.groundtruth import alignment, groundtruth_written, paired
from graphloc.pipelines.team_graph import TeamResult
from graphloc.names import out_path
from graphloc.plots import Series, plot_series, plot_trajectories
from graphloc.run import TeamRun


def plot_jobs(
    result: TeamResult,
    run: TeamRun,
    out: Path,
    truth: list,
    groundtruth_rate: str = "estimate",
    align: str | None = None,
) -> list[tuple[str, object]]:
    """(file name, job() -> Path or None) per figure: trajectories.png, error_over_time.png (with
    ground truth) and, online, latency.png (from latency.csv, written before)."""
    jobs = [("trajectories.png", lambda: _trajectories(result, run, out, truth, groundtruth_rate))]
    if any(g is not None for g in truth):
        jobs.append(("error_over_time.png", lambda: _errors(result, run, out, truth, align)))
    if result.mode == "online":
        jobs.append(("latency.png", lambda: _latency(result, run, out)))
    return jobs


def _moving(run: TeamRun, result: TeamResult) -> list[int]:
    """The robots drawn: not static, some pose estimated."""
    return [
        r
        for r, robot in enumerate(run.robots)
        if not robot.static and np.isfinite(result.estimate[r]).all(axis=1).any()
    ]


def _trajectories(
    result: TeamResult, run: TeamRun, out: Path, truth: list, groundtruth_rate: str
) -> Path:
    cmap = matplotlib.colormaps["tab10"]
    est, ref = [], []
    for r in _moving(run, result):
        rows = result.estimate[r]
        est.append(Series(f"{run.robots[r].name} {result.mode}", rows[:, :2], color=cmap(r % 10)))
        if truth[r] is not None:
            _, g_rows = groundtruth_written(truth[r], result.node_times[r], groundtruth_rate)
            ref.append(
                Series(
                    "ground truth" if not ref else "_nolegend_",
                    g_rows[:, :2],
                    style="--",
                    color="0.4",
                )
            )
    chosen = np.array([d.pose[:2] for d in result.decisions if d.committed >= 0]).reshape(-1, 2)
    if len(chosen):
        est.append(Series("committed candidates", chosen, style=".", color="tab:green"))
    rejected = rejected_candidates(run, result)
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
    return plot_trajectories(
        out_path(out, "trajectories.png"),
        est,
        ref,
        points if len(points) else None,
        title=f"{run.name}: {result.mode} (top view)",
        point_label="landmarks / markers",
    )


def _errors(result: TeamResult, run: TeamRun, out: Path, truth: list, align) -> Path | None:
    cmap = matplotlib.colormaps["tab10"]
    err = []
    for r in _moving(run, result):
        if truth[r] is None:
            continue
        try:
            t, e = ate_over_time(
                *paired(truth[r], result.node_times[r], result.estimate[r]),
                align=alignment(run, r, align),
                associated=True,
            )
        except ValueError:
            continue
        label = f"{run.robots[r].name} {result.mode}"
        err.append(Series(label, t - run.start_time, e, color=cmap(r % 10)))
    if not err:
        return None
    return plot_series(
        out_path(out, "error_over_time.png"),
        err,
        "time since start [s]",
        "position error [m]",
        f"{run.name}: error over time",
        logy=True,
    )


def _latency(result: TeamResult, run: TeamRun, out: Path) -> Path | None:
    csv_path = out_path(out, "latency.csv")
    if not csv_path.exists():
        return None
    table = np.genfromtxt(csv_path, delimiter=",", names=True).reshape(-1)
    if not len(table):
        return None
    lag = f"lag {result.lag:g} s" if result.lag else "full smoothing"
    series = [
        Series("wall", table["step"], table["latency_s"] * 1e3),
        Series("CPU", table["step"], table["cpu_s"] * 1e3, style="."),
    ]
    title = f"{run.name}: online latency ({lag}, latency.csv)"
    return plot_series(
        out_path(out, "latency.png"), series, "step", "latency per step [ms]", title, logy=True
    )


def rejected_candidates(run: TeamRun, result: TeamResult) -> np.ndarray:
    """World xy of every candidate the tracker did not commit (body position of the observer)."""
    out = [
        xyz[:2]
        for d in result.decisions
        for j, xyz in enumerate(d.candidates_xyz)
        if j != d.committed
    ]
    return np.array(out).reshape(-1, 2)
