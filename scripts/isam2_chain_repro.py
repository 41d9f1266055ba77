"""Minimal reproduction, GTSAM only (no graphloc import): per-update cost of `gtsam.ISAM2` on a
plain Pose2 chain, one pose, one odometry `BetweenFactorPose2` and (optionally) one
`PriorFactorPose2` per update. In a chain the update only re-eliminates the top of the Bayes
tree, so the per-update cost should stay flat; a cost that grows with the number of poses is a
walk over the whole tree.

    python scripts/isam2_chain_repro.py --poses 16000 [--variant NAME] [--first-prior-only]

Prints one JSON object: the GTSAM version, the variant's ISAM2Params, and the mean / median /
p95 thread CPU time per update [ms] over the first and the last tenth of the updates. Runs with
any Python that has gtsam and numpy (scripts/bench_isam2_chain.py runs it under several GTSAM
installs and writes docs/gtsam_isam2_chain.md).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from importlib import metadata

import gtsam
import numpy as np

# ISAM2Params variants: each a change from GTSAM's defaults that could avoid a whole-tree walk
VARIANTS = {
    "defaults": {},
    "no_relinearization": {"enableRelinearization": False},
    "relinearize_skip_1000": {"relinearizeSkip": 1000},
    "partial_relinearization_check": {"enablePartialRelinearizationCheck": True},
    "no_linearized_cache": {"cacheLinearizedFactors": False},
    "find_unused_factor_slots": {"findUnusedFactorSlots": True},
    "qr": {"factorization": "QR"},
}


def isam2_params(variant: str) -> gtsam.ISAM2Params:
    params = gtsam.ISAM2Params()
    for name, value in VARIANTS[variant].items():
        if name == "factorization":
            params.setFactorization(value)
        else:
            setattr(params, name, value)
    return params


def chain(poses: int, variant: str, prior_every_pose: bool) -> np.ndarray:
    """Thread CPU seconds of each `ISAM2.update` over a `poses`-long Pose2 chain."""
    isam = gtsam.ISAM2(isam2_params(variant))
    odo_noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.05, 0.05, 0.02]))
    prior_noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.5, 0.5, 0.2]))
    step = gtsam.Pose2(0.5, 0.0, 0.01)
    pose = gtsam.Pose2()
    cpu = np.zeros(poses)
    for i in range(poses):
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        if i == 0 or prior_every_pose:
            graph.add(gtsam.PriorFactorPose2(i, pose, prior_noise))
        if i > 0:
            graph.add(gtsam.BetweenFactorPose2(i - 1, i, step, odo_noise))
        values.insert(i, pose)
        c0 = time.thread_time()
        isam.update(graph, values)
        cpu[i] = time.thread_time() - c0
        pose = pose.compose(step)
    return cpu


def summary(cpu: np.ndarray) -> dict:
    n = max(len(cpu) // 10, 1)
    out = {}
    for name, part in (("first10", cpu[:n]), ("last10", cpu[-n:])):
        ms = part * 1e3
        out[name] = {
            "mean_ms": float(ms.mean()),
            "median_ms": float(np.median(ms)),
            "p95_ms": float(np.percentile(ms, 95)),
        }
    out["last_over_first_mean"] = out["last10"]["mean_ms"] / max(out["first10"]["mean_ms"], 1e-9)
    out["total_s"] = float(cpu.sum())
    bins = np.array_split(cpu * 1e3, 40)  # the per-update cost along the run, for a plot
    out["curve_poses"] = [int(sum(map(len, bins[:i])) + len(b) / 2) for i, b in enumerate(bins)]
    out["curve_mean_ms"] = [float(b.mean()) for b in bins]
    # per-update cost against the number of poses already in the tree: slope [ms per 1,000]
    out["slope_ms_per_1000_poses"] = float(np.polyfit(np.arange(len(cpu)), cpu * 1e3, 1)[0] * 1e3)
    return out


def gtsam_version() -> str:
    for dist in ("gtsam", "gtsam-develop"):
        try:
            return f"{dist} {metadata.version(dist)}"
        except metadata.PackageNotFoundError:
            continue
    return "unknown"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--poses", type=int, default=16000)
    parser.add_argument("--variant", choices=sorted(VARIANTS), default="defaults")
    parser.add_argument("--first-prior-only", action="store_true", help="no prior after pose 0")
    args = parser.parse_args(argv)
    if args.poses < 10:
        parser.error("--poses must be >= 10")
    cpu = chain(args.poses, args.variant, not args.first_prior_only)
    result = {
        "gtsam": gtsam_version(),
        "python": sys.version.split()[0],
        "poses": args.poses,
        "variant": args.variant,
        "params": VARIANTS[args.variant],
        "prior_every_pose": not args.first_prior_only,
        **summary(cpu),
    }
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
