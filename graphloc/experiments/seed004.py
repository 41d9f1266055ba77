"""Reproduce seed 004 (/work/shared/seeds/004_fa12d1d18dcbd0db.txt) Sec. III Table 1 (P3P
position error vs focal length and pixel noise) -- paper | raw P3P (seed baseline, ours) |
graphloc batch-smoothed track, same runs -- and a Fig. 3 style plot (a sinusoidal track: true
positions, every P3P candidate, the smoothed estimate). Library code: graphloc.tables,
graphloc.datasets.kaushik.

    .venv/bin/python scripts/repro_seed004.py [--quick] [--runs 1000 --frames 10] --out out/seed004

Writes <out>/seed004.json, <out>/seed004.md, <out>/table1_rms.png, <out>/fig3_track.png.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from graphloc import tables  # noqa: E402
from graphloc.geometry.resection import resection_covariance  # noqa: E402
from graphloc.datasets.kaushik import KaushikConfig, simulate  # noqa: E402


def plot_table(r: dict, path: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.8), sharey=True)
    for ax, variance in zip(axes, sorted({c["noise_variance"] for c in r["cells"]})):
        cells = [c for c in r["cells"] if c["noise_variance"] == variance]
        f = [c["focal_mm"] for c in cells]
        ax.plot(f, [c["paper"]["mean"] for c in cells], "k^--", label="paper (mean)")
        ax.plot(f, [c["seed_baseline_raw_p3p"]["rms"] for c in cells], "o-", label="raw P3P RMS (ours)")
        ax.plot(f, [c["graphloc_smoothed"]["rms"] for c in cells], "s-", label="graphloc smoothed RMS")
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
    have = g >= 0  # frames where P3P returned the genuine solution (else no candidate is plotted or used)
    R, t = np.tile(np.eye(3), (frames, 1, 1)), np.full((frames, 3), np.nan)
    cov = np.tile(np.eye(6), (frames, 1, 1))
    R[have], t[have] = run.candidates.R_wc[have, g[have]], run.candidates.t_wc[have, g[have]]
    cov[have] = resection_covariance(cfg.camera(), R[have], t[have], np.broadcast_to(run.leds, (int(have.sum()), 3, 3)),
                                     np.sqrt(cfg.noise_variance))
    smoothed = tables.smooth_track(R, np.nan_to_num(t), cov, have, run.odometry[0], cfg.odometry_noise,
                                   cfg.odometry_rot_sigma)
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


def run(out: Path, runs: int, frames: int, workers: int, progress: bool = True) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    r = tables.seed004_table_1(runs=runs, frames=frames, workers=workers, progress=progress)
    md = tables.markdown_seed004(r) + "\nTable 1 plot: table1_rms.png; Fig. 3 style: fig3_track.png.\n"
    (out / "seed004.json").write_text(json.dumps(r, indent=2, default=float))
    (out / "seed004.md").write_text(md)
    plot_table(r, out / "table1_rms.png")
    plot_fig3(out / "fig3_track.png")
    r["markdown"] = md
    r["wall_time_s"] = time.perf_counter() - t0
    return r


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000, help="tracks per cell (paper: 1000 runs)")
    parser.add_argument("--frames", type=int, default=10, help="frames per track")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--quick", action="store_true", help="CI size: 50 tracks per cell")
    parser.add_argument("--out", type=Path, default=Path("out/seed004"))
    args = parser.parse_args(argv)
    if args.quick:
        args.runs = min(args.runs, 50)
    print(run(args.out, args.runs, args.frames, args.workers)["markdown"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
