"""Reproduce seed 004 (004_fa12d1d18dcbd0db.txt) Sec. III Table 1 (P3P position error vs focal
length and pixel noise) -- paper | raw P3P (seed baseline, ours: the genuine candidate) |
graphloc -- and a Fig. 3 style plot (a sinusoidal track: true positions, every P3P candidate,
graphloc's estimate). Every run is a `graphloc simulate kaushik-p3p-error` log read by
`graphloc.datasets.open_run` and solved by `graphloc.pipelines.team_graph` (what `graphloc
smooth` runs); both columns come from the same logs.

    .venv/bin/python scripts/repro_seed004.py [--quick] [--runs 1000 --frames 10] --out DIR

Writes <out>/seed004.json, <out>/table1_rms.png, <out>/fig3_track.png and prints the table as
docs/results.md has it (benchmarks.render.results).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from graphloc.datasets.kaushik import (
    FOCALS_MM,
    NOISE_VARIANCES,
    KaushikConfig,
    KaushikP3PErrorScenario,
)
from benchmarks.trials import TrialExecutor
from benchmarks.front_door import simulated_run, truth_at
from benchmarks.render import render
from benchmarks.sizes import RunSizes, run_sizes
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.runner.team_run import team_graph
from graphloc.plots import plt
from graphloc.structured import dumps_json

# (focal mm, pixel noise variance) -> (mean, sigma) of the P3P position error [m], Table 1
PAPER_SEED004_TABLE_1 = {
    (16.0, 3.0): (0.0815, 0.0407),
    (26.0, 3.0): (0.0522, 0.0260),
    (36.0, 3.0): (0.0370, 0.0178),
    (16.0, 5.0): (0.1072, 0.0551),
    (26.0, 5.0): (0.0641, 0.0334),
    (36.0, 5.0): (0.0481, 0.0230),
    (16.0, 10.0): (0.1447, 0.0712),
    (26.0, 10.0): (0.0917, 0.0462),
    (36.0, 10.0): (0.0674, 0.0338),
}


def front_door_run(job: tuple) -> dict:
    """One track of a cell through the front door: `graphloc simulate kaushik-p3p-error` writes
    its log, `graphloc.datasets.open_run` reads it (P3P candidate sets from the logged pixels)
    and `graphloc.pipelines.team_graph` solves it in batch (what `graphloc smooth` runs). Per
    frame: the seed baseline's error (the genuine P3P candidate, nearest the truth; NaN where
    P3P gave none), graphloc's error, the camera's horizontal offset from the LED centroid and
    the LED circumradius (danger cylinder), the candidates and the estimate."""
    config, seed = job
    overrides = {k: v for k, v in asdict(config).items() if k not in ("runs", "seed")}
    run = simulated_run(KaushikP3PErrorScenario.name, seed, overrides)
    r = run.index("climber")
    result = solve(team_graph(run, GraphConfig()), "batch")
    times = result.node_times[r]
    truth = truth_at(run, r, times)
    raw = np.full(len(times), np.nan)
    candidates = []
    for o in run.observations:
        k = int(np.argmin(np.abs(times - o.time)))
        world = run.robots[o.target].initial_pose
        xyz = np.array(
            [
                world.compose(c).compose(o.body_T_sensor.inverse()).translation()
                for c in o.candidates.poses()
            ]
        )
        raw[k] = np.linalg.norm(xyz - truth[k], axis=1).min()
        candidates.append(xyz)
    est = result.estimate[r][:, :3]
    ground = run.robots[run.index("ground")]
    leds = np.array([ground.initial_pose.transformFrom(m) for m in ground.markers])
    centroid = leds.mean(axis=0)
    return {
        "raw": raw,
        "graphloc": np.linalg.norm(est - truth, axis=1),
        "offset": np.linalg.norm(truth[:, :2] - centroid[:2], axis=1),
        "radius": float(np.linalg.norm(leds[0] - centroid)),
        "truth": truth,
        "estimate": est,
        "candidates": candidates,
        "leds": leds,
    }


def _error_stats(err: np.ndarray) -> dict:
    e = err[np.isfinite(err)]
    return {
        "rms": float(np.sqrt(np.mean(e**2))) if e.size else None,
        "mean": float(e.mean()) if e.size else None,
        "std": float(e.std()) if e.size else None,
        "n": int(e.size),
    }


def seed004_cell(config: KaushikConfig, workers: int = 1) -> dict:
    """One cell of seed 004 Table 1 from `config.runs` simulated logs (seeds config.seed, +1,
    ...): the seed baseline (raw P3P, the genuine candidate) and graphloc (the logs through the
    front door, `front_door_run`) on the same runs."""
    jobs = [(config, config.seed + i) for i in range(config.runs)]
    with TrialExecutor(workers, progress=False) as ex:
        runs = list(ex.imap(front_door_run, jobs))
    raw_err = np.concatenate([x["raw"] for x in runs])
    smooth_err = np.concatenate([x["graphloc"] for x in runs])
    offset = np.concatenate([x["offset"] for x in runs])
    # evidence: P3P is singular when the camera is on the danger cylinder (through the LEDs,
    # axis normal to their plane; radius = circumradius) -- overhead views straddle it
    far = np.abs(offset - runs[0]["radius"]) > 0.5 * runs[0]["radius"]
    paper = PAPER_SEED004_TABLE_1.get((float(config.focal_mm), float(config.noise_variance)))
    return {
        "focal_mm": config.focal_mm,
        "noise_variance": config.noise_variance,
        "runs": config.runs,
        "frames": config.frames,
        "paper": None if paper is None else {"mean": paper[0], "std": paper[1]},
        "seed_baseline_raw_p3p": _error_stats(raw_err),
        "graphloc_smoothed": _error_stats(smooth_err),
        "graphloc_placed_runs": int(sum(np.isfinite(x["graphloc"]).any() for x in runs)),
        "frames_without_candidate": int(np.isnan(raw_err).sum()),
        "raw_p3p_rms_far_from_danger_cylinder": _error_stats(raw_err[far])["rms"],
        "raw_p3p_rms_near_danger_cylinder": _error_stats(raw_err[~far])["rms"],
        "candidates_per_frame_mean": float(
            np.mean([len(c) for x in runs for c in x["candidates"]])
        ),
    }


def seed004_table_1(
    runs: int = 1000,
    frames: int = 10,
    seed: int = 0,
    workers: int = 2,
    progress: bool = True,
    base: KaushikConfig = KaushikConfig(),
) -> dict:
    """Seed 004 Table 1: every (focal, noise) cell with `runs` tracks of `frames` updates;
    `base` holds the setup where the seed is silent (camera height, pixel pitch, offset: the
    readings of benchmarks.seed_baselines)."""
    t0 = time.perf_counter()
    cells = []
    grid = [(v, f) for v in NOISE_VARIANCES for f in FOCALS_MM]
    for i, (variance, focal) in enumerate(
        tqdm(grid, desc="seed 004 Table 1 cells", disable=not progress, leave=False)
    ):
        cfg = replace(
            base,
            focal_mm=focal,
            noise_variance=variance,
            runs=runs,
            frames=frames,
            seed=seed + i,
        )
        cells.append(seed004_cell(cfg, workers))
    below = all(c["graphloc_smoothed"]["rms"] < c["seed_baseline_raw_p3p"]["rms"] for c in cells)
    per_cell = ("focal_mm", "noise_variance", "runs", "frames", "seed")
    return {
        "table": "seed004-table1",
        "runs": runs,
        "frames": frames,
        "seed": seed,
        "setup": {k: v for k, v in asdict(base).items() if k not in per_cell},
        "cells": cells,
        "target_smoothed_below_raw_in_all_cells": below,
        "wall_time_s": time.perf_counter() - t0,
    }


def plot_table(r: dict, path: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.8), sharey=True)
    for ax, variance in zip(axes, sorted({c["noise_variance"] for c in r["cells"]})):
        cells = [c for c in r["cells"] if c["noise_variance"] == variance]
        f = [c["focal_mm"] for c in cells]
        ax.plot(f, [c["paper"]["mean"] for c in cells], "k^--", label="paper (mean)")
        ax.plot(
            f, [c["seed_baseline_raw_p3p"]["rms"] for c in cells], "o-", label="raw P3P RMS (ours)"
        )
        ax.plot(
            f, [c["graphloc_smoothed"]["rms"] for c in cells], "s-", label="graphloc smoothed RMS"
        )
        ax.set_title(f"pixel noise variance {variance:g}")
        ax.set_xlabel("focal length [mm]")
    axes[0].set_ylabel("position error [m]")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_fig3(path: Path, seed: int = 3, frames: int = 20) -> None:
    """One sinusoidal track (16 mm, variance 3) through the front door: truth, every P3P
    candidate (genuine / other) and graphloc's estimate, in the LED plane (seed 004 Fig. 3)."""
    x = front_door_run((KaushikConfig(runs=1, frames=frames), seed))
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    genuine, others = [], []
    for c, t in zip(x["candidates"], x["truth"]):
        j = int(np.argmin(np.linalg.norm(c - t, axis=1)))
        genuine.append(c[j])
        others += [p for i, p in enumerate(c) if i != j]
    genuine, others = np.array(genuine).reshape(-1, 3), np.array(others).reshape(-1, 3)
    ax.plot(others[:, 0], others[:, 1], "gx", ms=5, label="other P3P solutions")
    ax.plot(genuine[:, 0], genuine[:, 1], "c.", label="genuine P3P solution (raw)")
    ax.plot(x["truth"][:, 0], x["truth"][:, 1], "b-o", ms=3, label="true camera position")
    ax.plot(x["estimate"][:, 0], x["estimate"][:, 1], "r-s", ms=3, label="graphloc (front door)")
    ax.plot(x["leds"][:, 0], x["leds"][:, 1], "k+", ms=12, mew=2, label="LEDs")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=7)
    ax.set_title("Seed 004 Fig. 3 style: P3P solutions along a sinusoidal track")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(out: Path, sizes: RunSizes, workers: int, progress: bool = True) -> dict:
    """Table 1 at `sizes` and the Fig. 3 plot; JSON and plots to `out` (the table's markdown:
    benchmarks.render.results)."""
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    r = seed004_table_1(
        runs=sizes.seed004_runs, frames=sizes.seed004_frames, workers=workers, progress=progress
    )
    (out / "seed004.json").write_text(dumps_json(r, indent=2, default=float))
    plot_table(r, out / "table1_rms.png")
    plot_fig3(out / "fig3_track.png")
    r["wall_time_s"] = time.perf_counter() - t0
    return r


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="CI size (benchmarks.sizes)")
    parser.add_argument("--runs", type=int, help="tracks per cell (paper: 1000 runs)")
    parser.add_argument("--frames", type=int, help="frames per track")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("out/seed004"))
    args = parser.parse_args(argv)
    sizes = run_sizes(args.quick)
    sizes = replace(
        sizes,
        seed004_runs=args.runs or sizes.seed004_runs,
        seed004_frames=args.frames or sizes.seed004_frames,
    )
    result = run(args.out, sizes, args.workers)
    print(render("results_section", "seed004-table1", {"result": result}))
    return 0
