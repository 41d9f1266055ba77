"""The live API on a recorded team (issue 50): MRCLAM Dataset6's rows (all five robots) pushed
into `graphloc.LiveTeam` in time order, one iSAM2 update per completed step. Measures in one
run, against `graphloc online`'s solve of the same run (`open_run`, its graph, `solve(...,
"online")`):

- the per-step latency (`LiveUpdate.latency_s`: from the step's completion to its estimates;
  `cpu_s`: the CPU time of the same span, which other processes on a busy machine do not
  inflate) p50 / p95 / max, with and without each new pose's marginal covariance;
- the CPU time of the whole replay (open, every push, finish) with and without covariances,
  and its ratios to the online solve's CPU time (the peer in the same run);
- that the live estimates are the online ones (max abs difference of estimate and causal rows).

    .venv/bin/python scripts/bench_live.py --data ../shared/data/mrclam/MRCLAM_Dataset6 \\
        --json docs/results_live.json

docs/results_live_latency.md renders that JSON in its last section
(`scripts/render_docs.py results_live_latency.md`).
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
from tqdm import tqdm

from graphloc.datasets import open_run
from graphloc.live import LiveTeam, replay, run_rows
from graphloc.pipelines.team_graph import default_lag, solve
from graphloc.pipelines.team_graph.options import RunOptions
from graphloc.runner.team_run import team_graph
from graphloc.structured import dumps_json


def online(data: str, options: RunOptions) -> tuple[object, float, float]:
    """`graphloc online`'s read, graph and solve of the run: (TeamResult, CPU s, wall s)."""
    cpu0, wall0 = time.process_time(), time.perf_counter()
    run = open_run(data, duration=options.duration, noise=options.noise())
    config = options.graph_config()
    config = replace(config, lag=float(default_lag(run, config)))
    result = solve(team_graph(run, config), mode="online")
    return result, time.process_time() - cpu0, time.perf_counter() - wall0


def live(data: str, options: RunOptions, covariance: bool, progress: bool) -> dict:
    """The run's rows pushed in time order into a LiveTeam: result, CPU and wall time, the
    per-step latencies and the number of rows."""
    rows = list(run_rows(data, options))  # read before the clock starts: the rows "arrive"
    latencies: list = []
    cpus: list = []
    cpu0, wall0 = time.process_time(), time.perf_counter()
    team = LiveTeam.open(data, options, window=0.5)

    def listen(update):
        latencies.append(update.latency_s)
        cpus.append(update.cpu_s)

    team.subscribe(listen, covariance=covariance)
    what = "live replay" + (" (covariances)" if covariance else "")
    replay(team, tqdm(rows, desc=what, unit="row", disable=not progress, mininterval=2.0))
    result = team.finish()
    return {
        "result": result,
        "cpu_s": time.process_time() - cpu0,
        "wall_s": time.perf_counter() - wall0,
        "latencies": np.array(latencies),
        "cpus": np.array(cpus),
        "rows": len(rows),
    }


def quantiles(latencies: np.ndarray) -> dict:
    return {
        "p50_ms": float(np.percentile(latencies, 50) * 1e3),
        "p95_ms": float(np.percentile(latencies, 95) * 1e3),
        "max_ms": float(latencies.max() * 1e3),
        "mean_ms": float(latencies.mean() * 1e3),
    }


def largest_difference(a, b) -> float:
    out = 0.0
    for name in ("estimate", "causal"):
        for x, y in zip(getattr(a, name), getattr(b, name)):
            out = max(out, float(np.nanmax(np.abs(x - y), initial=0.0)))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default="../shared/data/mrclam/MRCLAM_Dataset6")
    parser.add_argument("--duration", type=float, default=None, help="first N seconds only")
    parser.add_argument("--json", default="out/bench_live/bench_live.json", help="output JSON")
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    options = RunOptions(duration=args.duration)
    progress = not args.no_progress
    reference, online_cpu, online_wall = online(args.data, options)
    plain = live(args.data, options, covariance=False, progress=progress)
    with_cov = live(args.data, options, covariance=True, progress=progress)
    graph = plain["result"].graph
    span = float(max(t[-1] for t in graph.node_times if len(t)) - graph.run.start_time)
    report = {
        "data": str(args.data),
        "duration_s": args.duration,
        "run_span_s": span,
        "robots": len(graph.run.robots),
        "rows": plain["rows"],
        "steps": len(graph.steps),
        "lag_s": graph.config.lag,
        "online": {"cpu_s": online_cpu, "wall_s": online_wall},
        "live": {
            "cpu_s": plain["cpu_s"],
            "wall_s": plain["wall_s"],
            "latency": quantiles(plain["latencies"]),
            "step_cpu": quantiles(plain["cpus"]),
            "cpu_per_row_us": plain["cpu_s"] / plain["rows"] * 1e6,
        },
        "live_with_covariance": {
            "cpu_s": with_cov["cpu_s"],
            "wall_s": with_cov["wall_s"],
            "latency": quantiles(with_cov["latencies"]),
            "step_cpu": quantiles(with_cov["cpus"]),
        },
        "ratios": {
            "live_cpu_over_online_cpu": plain["cpu_s"] / online_cpu,
            "live_with_covariance_cpu_over_online_cpu": with_cov["cpu_s"] / online_cpu,
            "covariance_cpu_over_live_cpu": with_cov["cpu_s"] / plain["cpu_s"],
            "realtime_factor_live": span / plain["wall_s"],
        },
        "max_abs_difference_live_vs_online": largest_difference(plain["result"], reference),
        "max_abs_difference_covariance_run_vs_online": largest_difference(
            with_cov["result"], reference
        ),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
    }
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(dumps_json(report) + "\n", encoding="utf-8")
    print(dumps_json({k: report[k] for k in ("live", "live_with_covariance", "ratios")}))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
