"""`graphloc smooth RUN --out DIR`: batch smoothing (Levenberg-Marquardt over the whole factor
graph) of a planar multi-robot run -- a graphloc log directory or an MRCLAM dataset directory.
Writes per-robot TUM trajectories, metrics.json (ATE/RPE vs ground truth for dead reckoning and
the estimate, skips, down-weighted measurements) and PNG plots."""

from __future__ import annotations

import argparse
import json

HELP = "batch factor-graph smoothing of a multi-robot run (log dir or MRCLAM dir): TUM, metrics JSON, PNGs"
MODE = "batch"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options shared by `smooth` and `online`."""
    parser.add_argument("run", help="graphloc log directory (manifest.json) or MRCLAM dataset directory")
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--duration", type=float, default=None, help="use only the first N seconds")
    parser.add_argument("--keyframe-dt", type=float, default=0.25, help="frame period [s] (default 0.25)")
    parser.add_argument("--no-landmarks", action="store_true", help="cooperative only: ignore landmark measurements")
    parser.add_argument("--no-inter-robot", action="store_true", help="ignore robot-to-robot measurements")
    parser.add_argument("--unknown-landmarks", action="store_true",
                        help="cooperative SLAM: estimate landmark positions instead of using the known map")
    parser.add_argument("--kernel", default="cauchy:2.0",
                        help="robust kernel NAME[:k] for measurement factors (huber, cauchy, tukey, gemanmcclure, dcs, none)")
    parser.add_argument("--odometry-kernel", default="none", help="robust kernel NAME[:k] for odometry factors")
    parser.add_argument("--bearing-sigma", type=float, default=0.02, help="bearing noise [rad]")
    parser.add_argument("--range-sigma", type=float, default=0.05, help="range noise at 0 m [m]")
    parser.add_argument("--range-sigma-per-m", type=float, default=0.035, help="range noise growth [m per m]")
    parser.add_argument("--no-progress", action="store_true", help="no tqdm progress bars")


def config_from_args(args: argparse.Namespace):
    from graphloc.factors.robust import Kernel, KernelPolicy
    from graphloc.pipeline_smoothing import SmoothingConfig

    kernel = Kernel.parse(args.kernel)
    kernels = KernelPolicy({"landmark": kernel, "inter_robot": kernel}, default=Kernel.parse(args.odometry_kernel))
    return SmoothingConfig(keyframe_dt=args.keyframe_dt, use_landmarks=not args.no_landmarks,
                           use_inter_robot=not args.no_inter_robot, landmark_priors=not args.unknown_landmarks,
                           kernels=kernels, bearing_sigma=args.bearing_sigma,
                           range_sigma=args.range_sigma, range_sigma_per_m=args.range_sigma_per_m)


def run_verb(args: argparse.Namespace, mode: str) -> int:
    from graphloc.pipeline_smoothing import run_and_report

    metrics = run_and_report(args.run, args.out, mode, config_from_args(args), duration=args.duration,
                             progress=not args.no_progress)
    summary = {name: {k: round(v["ate_rmse"], 4) for k, v in entry.items() if isinstance(v, dict)}
               for name, entry in metrics["per_robot"].items()}
    print(json.dumps({"mode": mode, "ate_rmse_m": summary, "realtime_factor": round(metrics["realtime_factor"], 1),
                      "downweighted": metrics["downweighted"], "skipped": metrics["skipped"]["counts"]}, indent=1))
    print(f"outputs in {args.out}")
    return 0


def run(args: argparse.Namespace) -> int:
    return run_verb(args, MODE)
