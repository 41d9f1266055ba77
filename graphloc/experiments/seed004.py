"""Reproduce seed 004 (004_fa12d1d18dcbd0db.txt) Sec. III Table 1 (P3P position error vs focal
length and pixel noise) -- paper | raw P3P (seed baseline, ours) | graphloc batch-smoothed
track (`graphloc.pipelines.track_smoothing`), same runs -- and a Fig. 3 style plot (a
sinusoidal track: true positions, every P3P candidate, the smoothed estimate). Simulation:
graphloc.datasets.kaushik.

    .venv/bin/python scripts/repro_seed004.py [--quick] [--runs 1000 --frames 10] --out DIR

Writes <out>/seed004.json, <out>/seed004.md, <out>/table1_rms.png, <out>/fig3_track.png.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from graphloc.candidates import CandidateSet
from graphloc.datasets.feng import odometry_covariance
from graphloc.datasets.kaushik import FOCALS_MM, NOISE_VARIANCES, KaushikConfig, simulate
from graphloc.executor import Executor
from graphloc.experiments import markdown
from graphloc.experiments.sizes import RunSizes, run_sizes
from graphloc.geometry.resection import resection_covariance
from graphloc.pipelines.track_smoothing import smooth_track
from graphloc.plots import plt
from graphloc.seams import Odometry

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


def genuine_track(
    R: np.ndarray,
    t: np.ndarray,
    cov: np.ndarray,
    have: np.ndarray,
    odometry: list,
    odometry_noise: float,
    odometry_rot_sigma: float,
) -> np.ndarray:
    """graphloc's estimate of one track (seed 004 Table 1 column): the genuine P3P candidate of
    every frame that has one (R (F,3,3), t (F,3), resection covariance (F,6,6); have (F,)) as a
    plain Gaussian prior, odometry (F-1 gtsam.Pose3 steps, covariance of
    graphloc.datasets.feng.odometry_covariance), batch-smoothed. Returns the centres (F,3)."""
    candidates = [
        CandidateSet(R[f][None], t[f][None], np.ones(1), time=float(f), covariance=cov[f][None])
        if have[f]
        else None
        for f in range(len(t))
    ]
    steps = [None] + [
        Odometry(o, odometry_covariance(o, odometry_noise, odometry_rot_sigma)) for o in odometry
    ]
    return smooth_track(candidates, steps, [0 if h else -1 for h in have])


def _smooth_chunk(job) -> np.ndarray:
    cand_R, cand_t, cand_cov, have, odometry, noise, rot = job
    return np.stack(
        [genuine_track(*args, noise, rot) for args in zip(cand_R, cand_t, cand_cov, have, odometry)]
    )


def _error_stats(err: np.ndarray) -> dict:
    e = err[np.isfinite(err)]
    return {
        "rms": float(np.sqrt(np.mean(e**2))),
        "mean": float(e.mean()),
        "std": float(e.std()),
        "n": int(e.size),
    }


def seed004_cell(config: KaushikConfig, workers: int = 1) -> dict:
    """One cell of seed 004 Table 1: raw P3P (genuine candidate) vs the smoothed track, same
    runs."""
    runs = simulate(config)
    N, F = runs.genuine.shape
    have = runs.genuine >= 0
    flat = np.flatnonzero(have.ravel())
    gidx = runs.genuine.ravel()[flat]
    R = np.zeros((N * F, 3, 3))
    R[:] = np.eye(3)
    t = np.zeros((N * F, 3))
    cov = np.broadcast_to(np.eye(6), (N * F, 6, 6)).copy()
    R[flat], t[flat] = runs.candidates.R_wc[flat, gidx], runs.candidates.t_wc[flat, gidx]
    sigma = config.pixel_sigma
    cov[flat] = resection_covariance(
        config.camera(), R[flat], t[flat], np.broadcast_to(runs.leds, (flat.size, 3, 3)), sigma
    )
    R, t, cov = R.reshape(N, F, 3, 3), t.reshape(N, F, 3), cov.reshape(N, F, 6, 6)
    chunks = [c for c in np.array_split(np.arange(N), max(1, min(N, 4 * workers))) if c.size]
    usable = have.any(axis=1)
    jobs = [
        (
            R[c][usable[c]],
            t[c][usable[c]],
            cov[c][usable[c]],
            have[c][usable[c]],
            [runs.odometry[i] for i in c if usable[i]],
            config.odometry_noise,
            config.odometry_rot_sigma,
        )
        for c in chunks
    ]
    smoothed = np.full((N, F, 3), np.nan)
    with Executor(workers, progress=False) as ex:
        for c, out in zip(chunks, ex.imap(_smooth_chunk, jobs)):
            if len(out):
                smoothed[c[usable[c]]] = out
    raw_err = np.where(have, runs.genuine_error, np.nan)
    smooth_err = np.linalg.norm(smoothed - runs.t_wc, axis=2)
    paper = PAPER_SEED004_TABLE_1.get((float(config.focal_mm), float(config.noise_variance)))
    # evidence: P3P is singular when the camera is on the danger cylinder (through the LEDs,
    # axis normal to their plane; radius = circumradius) -- overhead views straddle it
    radius = np.linalg.norm(runs.leds[0] - runs.leds.mean(axis=0))
    offset = np.linalg.norm(runs.t_wc[..., :2] - runs.leds.mean(axis=0)[:2], axis=2)
    far = np.abs(offset - radius) > 0.5 * radius
    return {
        "focal_mm": config.focal_mm,
        "noise_variance": config.noise_variance,
        "runs": N,
        "frames": F,
        "paper": None if paper is None else {"mean": paper[0], "std": paper[1]},
        "seed_baseline_raw_p3p": _error_stats(raw_err),
        "graphloc_smoothed": _error_stats(smooth_err),
        "frames_without_candidate": int((~have).sum()),
        "raw_p3p_rms_far_from_danger_cylinder": _error_stats(raw_err[far])["rms"]
        if far.any()
        else None,
        "raw_p3p_rms_near_danger_cylinder": _error_stats(raw_err[~far])["rms"]
        if (~far).any()
        else None,
        "candidates_per_frame_mean": float(runs.candidates.valid.sum(axis=1).mean()),
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
    readings of graphloc.experiments.seed_baselines)."""
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
    """One sinusoidal track (16 mm, variance 3): truth, all P3P candidates (genuine / invalid)
    and the smoothed estimate, in the LED plane (seed 004 Fig. 3)."""
    cfg = KaushikConfig(runs=1, frames=frames, seed=seed)
    run = simulate(cfg)
    valid = run.candidates.valid
    g = run.genuine[0]
    have = g >= 0  # frames where P3P returned the genuine solution (others: no candidate used)
    R, t = np.tile(np.eye(3), (frames, 1, 1)), np.full((frames, 3), np.nan)
    cov = np.tile(np.eye(6), (frames, 1, 1))
    R[have], t[have] = run.candidates.R_wc[have, g[have]], run.candidates.t_wc[have, g[have]]
    cov[have] = resection_covariance(
        cfg.camera(),
        R[have],
        t[have],
        np.broadcast_to(run.leds, (int(have.sum()), 3, 3)),
        cfg.pixel_sigma,
    )
    smoothed = genuine_track(
        R, np.nan_to_num(t), cov, have, run.odometry[0], cfg.odometry_noise, cfg.odometry_rot_sigma
    )
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    others = run.candidates.t_wc[valid & (np.arange(valid.shape[1])[None, :] != g[:, None])]
    ax.plot(others[:, 0], others[:, 1], "gx", ms=5, label="invalid P3P solutions")
    ax.plot(t[:, 0], t[:, 1], "c.", label="genuine P3P solution (raw)")
    ax.plot(run.t_wc[0, :, 0], run.t_wc[0, :, 1], "b-o", ms=3, label="true camera position")
    ax.plot(smoothed[:, 0], smoothed[:, 1], "r-s", ms=3, label="graphloc smoothed")
    ax.plot(run.leds[:, 0], run.leds[:, 1], "k+", ms=12, mew=2, label="LEDs")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=7)
    ax.set_title("Seed 004 Fig. 3 style: P3P solutions along a sinusoidal track")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(out: Path, sizes: RunSizes, workers: int, progress: bool = True) -> dict:
    """Table 1 at `sizes` and the Fig. 3 plot; JSON, markdown and plots to `out`."""
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    r = seed004_table_1(
        runs=sizes.seed004_runs, frames=sizes.seed004_frames, workers=workers, progress=progress
    )
    md = markdown.seed004(r) + "\nTable 1 plot: table1_rms.png; Fig. 3 style: fig3_track.png.\n"
    (out / "seed004.json").write_text(json.dumps(r, indent=2, default=float))
    (out / "seed004.md").write_text(md)
    plot_table(r, out / "table1_rms.png")
    plot_fig3(out / "fig3_track.png")
    r["markdown"] = md
    r["wall_time_s"] = time.perf_counter() - t0
    return r


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="CI size (graphloc.experiments.sizes)")
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
    print(run(args.out, sizes, args.workers)["markdown"])
    return 0
