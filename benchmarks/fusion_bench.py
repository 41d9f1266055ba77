"""Benchmark of inter-robot scan registration on `dual-robot-room` (issue 7, seed 004 Sec. IV-V).

Over random placements and headings of the two robots (one scenario seed each), per room
variant, in one run, three ways to get T_G0_C0 (first ceiling scan in the first ground scan):
  icp_no_guess   point-to-plane ICP from the identity (seed 004 Fig. 5: fails on inverted scans)
  fpfh_ransac    Open3D FPFH + RANSAC global registration, then the same ICP
  graphloc       P3P on the LEDs + HypothesisTracker over the ceiling robot's motion -> the same
                 ICP -> factor graph (graphloc.pipelines.map_fusion.fuse, map building skipped)
All three share the denoised clouds and the ICP settings. Success: rotation error < 2 deg and
translation error < 5 cm. Wall time per method = its initial guess + ICP (+ graph for graphloc);
KISS-ICP odometry (needed by graphloc's guess, and by every method to build the local maps)
is reported separately.

    .venv/bin/python scripts/bench_fusion.py --out out/bench_fusion            # 50 x 4 variants
    .venv/bin/python scripts/bench_fusion.py --quick --out out/bench_fusion_quick

`--real` (issue 16's protocol on a real indoor fragment): benchmarks.fusion_bench_real;
`--real --calibrate`: benchmarks.fusion_calibration; `--real --envelope` (the real
benchmark under other view noise and densities): benchmarks.fusion_envelope. Run
through scripts/bench_fusion.py (which keeps Open3D to one thread per process).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from benchmarks.trials import TrialExecutor
from benchmarks.fusion_bench_real import (
    PROTOCOL_KEEP,
    PROTOCOL_NOISE_M,
    TRANS_OK_M,
    main_real,
)
from benchmarks.fusion_calibration import main_calibrate
from benchmarks.fusion_envelope import main_envelope
from graphloc.structured import dumps_json

METHODS = ("icp_no_guess", "fpfh_ransac", "graphloc")
ROT_OK_DEG = 2.0


def run_trial(job: tuple[str, int, int]) -> dict:
    """One placement: simulate, then the three methods on the same clouds."""
    from graphloc.datasets.dual_room import DualRoomScenario, variant_config
    from graphloc.pipelines.map_fusion.fusion import fuse
    from graphloc.pipelines.map_fusion.options import FusionConfig
    from graphloc.mapping.odometry import OdometryConfig
    from graphloc.mapping.registration import (
        RegistrationConfig,
        global_fpfh_ransac,
        pose_errors,
        prepare,
        refine,
    )

    variant, seed, frames = job
    scenario = DualRoomScenario.simulate(variant_config(variant, seed, frames=frames))
    truth = scenario.T_ground0_ceiling0
    reg_cfg = RegistrationConfig()
    t0 = time.perf_counter()
    target = prepare(scenario.scans["ground"][0], reg_cfg)
    source = prepare(scenario.scans["ceiling"][0], reg_cfg)
    prep_s = time.perf_counter() - t0
    out = {
        "variant": variant,
        "seed": seed,
        "denoise_s": prep_s,
        "overlap_points": [len(source.points), len(target.points)],
    }

    r = refine(source, target, np.eye(4), reg_cfg)
    out["icp_no_guess"] = dict(
        zip(("rot_deg", "trans_m"), pose_errors(r.transformation, truth)),
        iterations=r.iterations,
        seconds=r.seconds,
        fitness=r.fitness,
    )

    T_glob, glob_s = global_fpfh_ransac(source, target, reg_cfg, seed=seed)
    g_rot, g_tr = pose_errors(T_glob, truth)
    r = refine(source, target, T_glob, reg_cfg)
    out["fpfh_ransac"] = dict(
        zip(("rot_deg", "trans_m"), pose_errors(r.transformation, truth)),
        iterations=r.iterations,
        seconds=glob_s + r.seconds,
        fitness=r.fitness,
        guess_rot_deg=g_rot,
        guess_trans_m=g_tr,
    )

    cfg = FusionConfig(
        odometry=OdometryConfig(threads=1),
        registration=reg_cfg,
        build_map=False,
        scan_matching=False,
    )
    res = fuse(scenario.fusion_input(), cfg)
    g_rot, g_tr = pose_errors(res.guess, truth)
    secs = res.timings["p3p_tracker_s"] + res.timings["icp_s"] + res.timings["graph_s"]
    out["graphloc"] = dict(
        zip(("rot_deg", "trans_m"), pose_errors(res.T_g0_c0, truth)),
        iterations=res.registration.iterations,
        seconds=secs,
        fitness=res.registration.fitness,
        guess_rot_deg=g_rot,
        guess_trans_m=g_tr,
        locked=res.guess_info.locked,
        p3p_frames=int(len(res.guess_info.frames)),
        p3p_factors=res.n_p3p_factors,
        icp_only_rot_deg=pose_errors(res.registration.transformation, truth)[0],
    )
    out["odometry_s"] = res.timings["odometry_s"]
    return out


def summarize(rows: list[dict]) -> dict:
    summary = {}
    for variant in sorted({r["variant"] for r in rows}):
        vr = [r for r in rows if r["variant"] == variant]
        summary[variant] = {
            "trials": len(vr),
            "odometry_s_median": float(np.median([r["odometry_s"] for r in vr])),
            "denoise_s_median": float(np.median([r["denoise_s"] for r in vr])),
        }
        for m in METHODS:
            rot = np.array([r[m]["rot_deg"] for r in vr])
            tr = np.array([r[m]["trans_m"] for r in vr])
            ok = (rot < ROT_OK_DEG) & (tr < TRANS_OK_M)
            summary[variant][m] = {
                "success_rate": float(ok.mean()),
                "rot_deg_median": float(np.median(rot)),
                "rot_deg_max": float(rot.max()),
                "trans_m_median": float(np.median(tr)),
                "trans_m_max": float(tr.max()),
                "rot_deg_median_successes": float(np.median(rot[ok])) if ok.any() else None,
                "trans_m_median_successes": float(np.median(tr[ok])) if ok.any() else None,
                "icp_iterations_median": float(np.median([r[m]["iterations"] for r in vr])),
                "seconds_median": float(np.median([r[m]["seconds"] for r in vr])),
                "seconds_total": float(np.sum([r[m]["seconds"] for r in vr])),
            }
        g, f = summary[variant]["graphloc"], summary[variant]["fpfh_ransac"]
        summary[variant]["graphloc_vs_fpfh_time_ratio"] = g["seconds_total"] / f["seconds_total"]
        summary[variant]["targets_met"] = {
            "graphloc_100pct": g["success_rate"] == 1.0,
            "graphloc_ge_fpfh": g["success_rate"] >= f["success_rate"],
            "median_rot_le_0.1deg": g["rot_deg_median"] <= 0.1,
            "median_trans_le_1cm": g["trans_m_median"] <= 0.01,
            "faster_than_fpfh": g["seconds_total"] < f["seconds_total"],
        }
    return summary


def plot(rows: list[dict], path: Path) -> None:
    from graphloc.plots import plt  # the one place that sets the backend

    variants = sorted({r["variant"] for r in rows})
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    for ax, (key, label, floor) in zip(
        axes,
        (
            ("rot_deg", "rotation error [deg]", 1e-3),
            ("trans_m", "translation error [m]", 1e-4),
            ("seconds", "wall time [s]", 1e-3),
        ),
    ):
        for i, m in enumerate(METHODS):
            data = [
                np.maximum([r[m][key] for r in rows if r["variant"] == v], floor) for v in variants
            ]
            pos = np.arange(len(variants)) * 4 + i
            ax.boxplot(
                data,
                positions=pos,
                widths=0.8,
                patch_artist=True,
                boxprops=dict(facecolor=f"C{i}", alpha=0.6),
                medianprops=dict(color="k"),
            )
            ax.plot([], [], color=f"C{i}", lw=8, alpha=0.6, label=m)
        ax.set_yscale("log")
        ax.set_xticks(np.arange(len(variants)) * 4 + 1, variants)
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        if key == "rot_deg":
            ax.axhline(ROT_OK_DEG, color="r", ls="--", lw=1)
        if key == "trans_m":
            ax.axhline(TRANS_OK_M, color="r", ls="--", lw=1)
    axes[0].legend(loc="upper left", fontsize=8)
    fig.suptitle(f"dual-robot-room registration, {len(rows)} placements")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ------------------------------------------------------------------ real fragment (issue 16)


def main(argv=None) -> int:
    from graphloc.datasets.dual_room import VARIANTS

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--trials", type=int, default=50, help="placements per room variant")
    p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    p.add_argument("--frames", type=int, default=5, help="scan / camera frames per robot")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--seed", type=int, default=0, help="first scenario seed")
    p.add_argument("--quick", action="store_true", help="CI size: 3 placements per variant")
    p.add_argument(
        "--out", default=None, help="default out/bench_fusion (out/bench_fusion_real with --real)"
    )
    p.add_argument("--real", action="store_true", help="issue 16's protocol on the real fragment")
    p.add_argument("--doc", default=None, help="with --real: also write the markdown table here")
    p.add_argument(
        "--fragment",
        default=None,
        help="with --real: a gravity-aligned (z up) real scan, PLY / PCD / XYZ "
        "(default: the bundled tests/data/real_room fragment)",
    )
    p.add_argument(
        "--noise",
        type=float,
        default=PROTOCOL_NOISE_M,
        help="with --real: each view's Gaussian noise [m] (issue 16's protocol: 0.005)",
    )
    p.add_argument(
        "--keep",
        type=float,
        default=PROTOCOL_KEEP,
        help="with --real: the fraction of the fragment's points each view keeps (protocol: 0.5)",
    )
    p.add_argument(
        "--calibrate",
        action="store_true",
        help="with --real: fit the registration covariance's calibration (use other seeds)",
    )
    p.add_argument(
        "--envelope",
        action="store_true",
        help="with --real: the benchmark under other view noise and densities (use other seeds)",
    )
    p.add_argument(
        "--calibration-json",
        default="docs/results_fusion_calibration.json",
        help="with --calibrate: where the fit goes",
    )
    args = p.parse_args(argv)
    if args.out is None:
        args.out = "out/bench_fusion_real" if args.real else "out/bench_fusion"
        args.out += "_envelope" if args.real and args.envelope else ""
    if args.real:
        if args.trials < 1 or args.workers < 1 or args.noise < 0 or not 0 < args.keep <= 1:
            raise SystemExit("--trials >= 1, --workers >= 1, --noise >= 0, 0 < --keep <= 1")
        if args.calibrate and args.envelope:
            raise SystemExit("--calibrate and --envelope are two runs: give one")
        if args.envelope:
            if (args.noise, args.keep) != (PROTOCOL_NOISE_M, PROTOCOL_KEEP):
                raise SystemExit("--envelope sets the views' noise and kept fraction itself")
            return main_envelope(args)
        return main_calibrate(args) if args.calibrate else main_real(args)
    trials = 3 if args.quick else args.trials
    if trials < 1 or args.frames < 2 or args.workers < 1:
        raise SystemExit("--trials >= 1, --frames >= 2, --workers >= 1")
    jobs = [(v, args.seed + i, args.frames) for v in args.variants for i in range(trials)]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with TrialExecutor(args.workers) as ex:
        rows = list(ex.imap(run_trial, jobs, desc="placements"))
    rows.sort(key=lambda r: (r["variant"], r["seed"]))
    summary = summarize(rows)
    report = {
        "benchmark": "fusion",
        "trials_per_variant": trials,
        "frames": args.frames,
        "workers": args.workers,
        "success": {"rot_deg": ROT_OK_DEG, "trans_m": TRANS_OK_M},
        "wall_time_s": time.perf_counter() - start,
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "load_avg_1m_at_end": os.getloadavg()[0],
        },
        "summary": summary,
        "trials": rows,
    }
    (out / "bench_fusion.json").write_text(dumps_json(report, indent=1))
    plot(rows, out / "bench_fusion.png")
    for v, s in summary.items():
        line = " | ".join(
            f"{m}: {100 * s[m]['success_rate']:.0f}% rot {s[m]['rot_deg_median']:.3f} deg "
            f"trans {100 * s[m]['trans_m_median']:.2f} cm {s[m]['seconds_median']:.2f} s"
            for m in METHODS
        )
        print(f"{v:12s} {line}")
    print(f"wrote {out / 'bench_fusion.json'} and {out / 'bench_fusion.png'}")
    return 0
