"""Online and batch at scale (issue 15) on MRCLAM Dataset6: graphloc batch vs GTSAM-only LM
on the same graph, online with full iSAM2 and fixed lags (latency first vs last tenth, slowest
step, real-time factor, ATE vs batch, memory), and the run replayed COPIES times with a
shifted clock through the default lag. Writes bench_scale.json (every number computed here)
and, with --markdown, docs/results_scale.md from it (benchmarks.render.scale), its JSON and
its PNG beside it.

    .venv/bin/python scripts/bench_scale.py --out out/bench_scale --markdown docs/results_scale.md

`--duration` / `--copies` / `--lags` shrink it for a quick check.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from graphloc.datasets import open_run

from graphloc.pipelines.team_graph import DEFAULT_LAG
from graphloc.runner.team_run import team_graph
from benchmarks.scale import (
    gtsam_only_batch,
    observation_gaps,
    repeated_online_cpu,
    online_profile,
    online_summary,
    replay_graph,
    rss_mb,
    tenth_error_ratios,
)
from benchmarks.markdown import write_report
from benchmarks.render import render
from graphloc.pipelines.report import evaluate
from graphloc.pipelines.team_graph import GraphConfig, solve, warm_starts
from graphloc.plots import plt
from graphloc.structured import dumps_json


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default="../shared/data/mrclam/MRCLAM_Dataset6")
    parser.add_argument("--out", default="out/bench_scale")
    parser.add_argument("--duration", type=float, default=None, help="first N seconds only")
    lags = ",".join(f"{x:g}" for x in sorted({0, 20, 30, 40, DEFAULT_LAG}))
    parser.add_argument(
        "--lags",
        default=lags,
        help="online lags [s] to measure (0: full iSAM2; the default always)",
    )
    parser.add_argument("--copies", type=int, default=10, help="replays in the long run")
    parser.add_argument(
        "--relinearize",
        default="0.05,0.01",
        help="iSAM2 translation relinearize thresholds [m] to measure at the default lag",
    )
    parser.add_argument(
        "--marginalize-every",
        default="1,2",
        help="fixed-lag batch sizes [s] to measure at the default lag (beside the default's)",
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=3,
        help="solves of the default lag for CPU costs as each step's least time (0: none)",
    )
    parser.add_argument("--markdown", type=Path, default=None, help="write the results table")
    parser.add_argument(
        "--from-json",
        type=Path,
        default=None,
        help="no runs: --markdown and its PNG from this bench_scale.json",
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    if args.from_json is not None:
        write(json.loads(args.from_json.read_text()), out, args.markdown)
        return 0

    run = open_run(args.data, args.duration)
    t0 = time.perf_counter()
    graph = team_graph(run, GraphConfig())
    report = {
        "data": str(args.data),
        "run": run.name,
        "duration_s": run.end_time - run.start_time,
        "python": sys.version.split()[0],
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "load_average_at_start": os.getloadavg(),
        "build_s": time.perf_counter() - t0,
        "counts": graph.counts,
        "default_lag_s": DEFAULT_LAG,
        "marginalize_every_s": GraphConfig().marginalize_every,
        "relinearize_threshold_default": GraphConfig()
        .session_config("online", graph.precision)
        .relinearize_threshold,
        "relinearize_translation_default": GraphConfig()
        .session_config("online", graph.precision)
        .relinearize_translation,
    }

    # the long run first: its memory slope is then not hidden by pages earlier solves freed
    long = None
    if args.copies > 1:
        result, cpu, samples = online_profile(replay_graph(graph, args.copies), DEFAULT_LAG)
        long = online_summary(result, cpu, samples, run, None)
        long["copies"] = args.copies
        del result
        print("long run", dumps_json(long), flush=True)

    # batch: graphloc vs GTSAM alone, same graph, same process
    c0 = time.process_time()
    batch = solve(graph, "batch")
    batch_cpu = time.process_time() - c0
    metrics = evaluate(batch, run, align="se2")  # as MRCLAM results are reported
    batch_ate = {
        n: e["batch"]["ate_rmse"]
        for n, e in metrics["per_robot"].items()
        if isinstance(e.get("batch"), dict) and "ate_rmse" in e["batch"]
    }
    alone = gtsam_only_batch(graph)
    # GTSAM alone from graphloc's warm start (the incremental pass LM starts from, `solve`)
    alone_warm = gtsam_only_batch(graph, warm_starts(graph)[0])
    report["batch"] = {
        "graphloc_wall_s": batch.wall_s,
        "graphloc_cpu_s": batch_cpu,
        "graphloc_error": batch.error,
        "gtsam_only": alone,
        "gtsam_only_from_warm_start": alone_warm,
        "ratio_wall": batch.wall_s / alone["wall_s"],
        "ratio_cpu": batch_cpu / alone["cpu_s"],
        "ate_rmse_m": batch_ate,
        "realtime_factor": metrics["realtime_factor"],
    }
    print("batch", dumps_json(report["batch"]), flush=True)

    report["online"] = {}
    for lag in sorted({float(x) for x in args.lags.split(",") if x} | {DEFAULT_LAG}):
        result, cpu, samples = online_profile(graph, lag or None)
        summary = online_summary(result, cpu, samples, run, batch_ate)
        report["online"][f"{lag:g}"] = summary
        print("online lag", lag, dumps_json(summary), flush=True)
        if lag == DEFAULT_LAG:  # where along the run the default lag loses to batch, and why
            report["lookahead"] = {
                "robots": [robot.name for robot in run.robots],
                "gaps": observation_gaps(graph),
                "tenth_error_ratio_default_lag": tenth_error_ratios(result, batch, run),
            }
        del result

    # the default lag solved again: each step's least CPU time over the repeats
    if args.repeats > 0:
        report["online_repeated"] = repeated_online_cpu(graph, DEFAULT_LAG, args.repeats)
        print("repeated", dumps_json(report["online_repeated"]), flush=True)

    # the default lag at smaller relinearization thresholds: ATE against CPU
    report["online_relinearize"] = {}
    for thr in (float(x) for x in args.relinearize.split(",") if x):
        res, cpu, samples = online_profile(graph, DEFAULT_LAG, relinearize_translation=thr)
        report["online_relinearize"][f"{thr:g}"] = online_summary(res, cpu, samples, run, batch_ate)
        print("relinearize", thr, dumps_json(report["online_relinearize"][f"{thr:g}"]), flush=True)

    # the default lag with other marginalization batch sizes: latency trend against CPU
    report["online_marginalize_every"] = {}
    for every in (float(x) for x in args.marginalize_every.split(",") if x):
        res, cpu, samples = online_profile(graph, DEFAULT_LAG, marginalize_every=every)
        summary = online_summary(res, cpu, samples, run, batch_ate)
        report["online_marginalize_every"][f"{every:g}"] = summary
        print("marginalize every", every, dumps_json(summary), flush=True)

    base = report["online"].get(f"{DEFAULT_LAG:g}")
    if long is not None and base:
        long["p95_latency_over_single_run"] = long["latency_ms"]["p95"] / base["latency_ms"]["p95"]
        long["p95_cpu_over_single_run"] = (
            long["trend"]["cpu_p95_last10_ms"] / base["trend"]["cpu_p95_last10_ms"]
        )
        report["long_run"] = long

    report["rss_mb_end"] = rss_mb()
    report["load_average_at_end"] = os.getloadavg()
    write(json.loads(dumps_json(report, default=str)), out, args.markdown)
    return 0


def write(report: dict, out: Path, doc: Path | None) -> None:
    """OUT/bench_scale.json and .md; the doc (`doc`, e.g. docs/results_scale.md), its JSON and
    its PNG beside it when given."""
    text = render("scale", report, doc=doc.stem if doc is not None else "results_scale")
    write_report(out, "bench_scale", report, text, doc, rendered=report)
    if doc is not None:
        plot(report, doc.with_suffix(".png"))
    print(f"wrote {out / 'bench_scale.json'}" + (f", {doc} and its JSON and PNG" if doc else ""))


def plot(r: dict, path) -> None:
    """docs/results_scale.png: per lag (full iSAM2 at the left), each robot's online ATE over
    batch, the real-time factor (CPU) and the p95 step CPU of the first and last tenth, with
    issue 15's targets as dashed lines."""
    lags = list(r["online"])
    x = np.arange(len(lags))
    names = ["full" if k == "0" else f"{k} s" for k in lags]
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    for robot in r["batch"]["ate_rmse_m"]:
        y = [r["online"][k]["ate_over_batch"].get(robot, np.nan) for k in lags]
        ax[0].plot(x, y, "o-", label=robot)
    ax[0].axhline(1.10, ls="--", c="k", lw=1, label="target 1.10")
    ax[0].set(ylabel="online ATE / batch ATE", title="accuracy")
    ax[0].legend(fontsize=7)
    ax[1].bar(x, [r["online"][k]["realtime_factor_cpu"] for k in lags], color="tab:blue")
    ax[1].axhline(100, ls="--", c="k", lw=1, label="target 100x")
    ax[1].set(ylabel="run duration / solve CPU", title="real-time factor")
    ax[1].legend(fontsize=7)
    for key, label in (("cpu_p95_first10_ms", "first 10 %"), ("cpu_p95_last10_ms", "last 10 %")):
        ax[2].plot(x, [r["online"][k]["trend"][key] for k in lags], "o-", label=label)
    ax[2].set(ylabel="p95 step CPU [ms]", title="per-step cost, first vs last tenth")
    ax[2].legend(fontsize=7)
    for a in ax:
        a.set_xticks(x, names)
        a.set_xlabel("online lag")
        a.grid(alpha=0.3)
    fig.suptitle(
        f"{r['run']}: online iSAM2, full and fixed lags (default {r['default_lag_s']:g} s)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
