"""MRCLAM benchmark: dead reckoning vs batch (LM) vs online (iSAM2) smoothing on a whole MRCLAM
dataset (default Dataset6, all robots), with and without landmarks, plus cooperative SLAM
(landmark positions unknown, batch). Writes bench_mrclam.json (every number computed here),
per-configuration outputs (TUM, metrics.json, PNGs) and ate_per_robot.png, and checks the bar:

- landmarks + inter-robot (batch): every robot's ATE RMSE >= 5x lower than dead reckoning;
- inter-robot only (batch): every robot better than dead reckoning;
- online ATE within 20 % of batch ATE (every robot, landmarks + inter-robot);
- online >= 50x faster than real time (run duration / online solve wall time, this run).

Online is the product's default online path, what `graphloc online` runs without `--lag`: the
fixed lag `default_lag(run, config)` chooses for the configuration (full smoothing where a
variable lives all run long, e.g. cooperative SLAM's landmarks).

    .venv/bin/python scripts/bench_mrclam.py --data ../shared/data/mrclam/MRCLAM_Dataset6 \\
        --out out/bench_mrclam

Everything goes through the path `graphloc smooth` / `online` take: `graphloc.datasets.open_run`
and `graphloc.pipelines.team_graph` (SE(3) poses, planar robots held to the floor plane).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from graphloc.datasets import open_run
from graphloc.pipelines.report import evaluate, write_outputs
from graphloc.pipelines.team_graph import GraphConfig, default_lag, solve
from graphloc.runner.team_run import team_graph
from graphloc.plots import Series, plot_series
from graphloc.structured import dumps_json

CONFIGS = {
    "landmarks+inter_robot": (GraphConfig(), ("batch", "online")),
    "inter_robot_only": (GraphConfig(use_landmarks=False), ("batch", "online")),
    "cooperative_slam": (GraphConfig(landmark_priors=False), ("batch",)),
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--data", default="../shared/data/mrclam/MRCLAM_Dataset6", help="MRCLAM dir or graphloc log"
    )
    parser.add_argument("--out", default="out/bench_mrclam", help="output directory")
    parser.add_argument(
        "--duration", type=float, default=None, help="first N seconds only (for quick iteration)"
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    run = open_run(args.data, args.duration)
    names = [r.name for r in run.robots]
    report = {
        "data": str(args.data),
        "run": run.name,
        "robots": names,
        "duration_s": run.end_time - run.start_time,
        "python": sys.version.split()[0],
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "load_average_at_start": os.getloadavg(),
        "configs": {},
    }
    results = {}
    for name, (config, modes) in CONFIGS.items():
        t0 = time.perf_counter()
        problem = team_graph(run, config)
        build_s = time.perf_counter() - t0
        lag = default_lag(run, config)
        for mode in modes:
            cpu0 = time.process_time()
            if mode == "online":  # the default online path: `graphloc online` without --lag
                problem = replace(problem, config=replace(problem.config, lag=lag))
            result = solve(problem, mode, progress=True)
            cpu = time.process_time() - cpu0
            metrics = evaluate(result, run, align="se2")  # as MRCLAM results are reported
            metrics["solve_cpu_s"] = cpu
            metrics["realtime_factor_cpu"] = metrics["duration_s"] / max(cpu, 1e-12)
            metrics["build_s"] = build_s
            write_outputs(result, run, metrics, out / name / mode)
            results[(name, mode)] = metrics
            report["configs"].setdefault(name, {})[mode] = {
                k: metrics[k]
                for k in (
                    "solve_wall_s",
                    "solve_cpu_s",
                    "build_s",
                    "realtime_factor",
                    "realtime_factor_cpu",
                    "latency_ms",
                    "downweighted",
                    "counts",
                    "skipped",
                )
            }
            report["configs"][name][mode]["lag_s"] = lag if mode == "online" else None
            report["configs"][name][mode]["ate_rmse_m"] = {
                r: {track: e[track]["ate_rmse"] for track in e if isinstance(e[track], dict)}
                for r, e in metrics["per_robot"].items()
                if e.get("groundtruth")
            }
            report["configs"][name][mode]["rpe_trans_rmse_m"] = {
                r: e[mode]["rpe_trans_rmse"]
                for r, e in metrics["per_robot"].items()
                if e.get("groundtruth")
            }
            print(
                f"{name:24s} {mode:6s} wall {metrics['solve_wall_s']:7.2f} s  "
                f"real-time x{metrics['realtime_factor']:7.1f}  "
                "ATE "
                + " ".join(
                    f"{r}:{e[mode]['ate_rmse']:.3f}/{e['dead_reckoning']['ate_rmse']:.3f}"
                    for r, e in metrics["per_robot"].items()
                    if e.get("groundtruth")
                ),
                flush=True,
            )

    robots = [
        r
        for r in names
        if results[("landmarks+inter_robot", "batch")]["per_robot"][r].get("groundtruth")
    ]

    def ate(cfg, mode, robot, track=None):
        return results[(cfg, mode)]["per_robot"][robot][track or mode]["ate_rmse"]

    full_ratio = {
        r: ate("landmarks+inter_robot", "batch", r, "dead_reckoning")
        / ate("landmarks+inter_robot", "batch", r)
        for r in robots
    }
    coop_ratio = {
        r: ate("inter_robot_only", "batch", r, "dead_reckoning")
        / ate("inter_robot_only", "batch", r)
        for r in robots
    }
    online_rel = {
        r: ate("landmarks+inter_robot", "online", r) / ate("landmarks+inter_robot", "batch", r)
        for r in robots
    }
    rt = results[("landmarks+inter_robot", "online")]["realtime_factor"]
    bar = {
        "dead_reckoning_over_batch_ate_ratio": full_ratio,
        "min_ratio_landmarks+inter_robot": min(full_ratio.values()),
        "pass_5x_lower_than_dead_reckoning": bool(min(full_ratio.values()) >= 5.0),
        "dead_reckoning_over_batch_ate_ratio_inter_robot_only": coop_ratio,
        "pass_inter_robot_only_better_than_dead_reckoning": bool(min(coop_ratio.values()) > 1.0),
        "online_over_batch_ate": online_rel,
        "pass_online_within_20pct_of_batch": bool(max(online_rel.values()) <= 1.2),
        "online_realtime_factor": rt,
        "online_realtime_factor_cpu": results[("landmarks+inter_robot", "online")][
            "realtime_factor_cpu"
        ],
        "pass_online_50x_realtime": bool(rt >= 50.0),
    }
    bar["pass_all"] = all(v for k, v in bar.items() if k.startswith("pass_"))
    report["bar"] = bar
    report["load_average_at_end"] = os.getloadavg()
    (out / "bench_mrclam.json").write_text(dumps_json(report, indent=2) + "\n")

    series = []
    x = np.arange(len(robots), dtype=float)
    for (cfg, mode), metrics in results.items():
        series.append(
            Series(
                f"{cfg} {mode}",
                x,
                np.array([metrics["per_robot"][r][mode]["ate_rmse"] for r in robots]),
                style="o-",
            )
        )
    series.append(
        Series(
            "dead reckoning",
            x,
            np.array([ate("landmarks+inter_robot", "batch", r, "dead_reckoning") for r in robots]),
            style="ks--",
        )
    )
    plot_series(
        out / "ate_per_robot.png",
        series,
        "robot index (" + ", ".join(robots) + ")",
        "ATE RMSE [m] (SE(2)-aligned)",
        f"{run.name}: ATE per robot",
        logy=True,
    )
    print(dumps_json(bar, indent=1))
    print(f"wrote {out / 'bench_mrclam.json'}")
    return 0 if bar["pass_all"] else 1
