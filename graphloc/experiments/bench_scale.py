"""Online and batch at scale (issue 15) on MRCLAM Dataset6: graphloc batch vs GTSAM-only LM
on the same graph, online with full iSAM2 and fixed lags (latency first vs last tenth, slowest
step, real-time factor, ATE vs batch, memory), and the run replayed COPIES times with a
shifted clock through the default lag. Writes bench_scale.json (every number computed here)
and, with --markdown, docs/results_scale.md from it and a copy of the JSON beside it.

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

from graphloc.datasets import open_run

from graphloc.pipelines.team_graph import DEFAULT_LAG
from graphloc.experiments.scale import (
    gtsam_only_batch,
    known_landmarks_unary,
    online_profile,
    online_summary,
    replay_graph,
    rss_mb,
)
from graphloc.pipelines.report import evaluate
from graphloc.pipelines.team_graph import GraphConfig, build_graph, solve


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default="../shared/data/mrclam/MRCLAM_Dataset6")
    parser.add_argument("--out", default="out/bench_scale")
    parser.add_argument("--duration", type=float, default=None, help="first N seconds only")
    lags = ",".join(f"{x:g}" for x in sorted({0, 20, 30, 40, DEFAULT_LAG}))
    parser.add_argument("--lags", default=lags, help="online lags [s] to measure, 0 = full iSAM2")
    parser.add_argument("--copies", type=int, default=10, help="replays in the long run")
    parser.add_argument(
        "--relinearize",
        default="0.02,0.01",
        help="iSAM2 relinearize thresholds to measure at the default lag (beside the run's own)",
    )
    parser.add_argument(
        "--marginalize-every",
        default="1,2",
        help="fixed-lag batch sizes [s] to measure at the default lag (beside the default's)",
    )
    parser.add_argument("--markdown", type=Path, default=None, help="write the results table")
    parser.add_argument(
        "--from-json",
        type=Path,
        default=None,
        help="only write --markdown from this bench_scale.json",
    )
    args = parser.parse_args(argv)
    if args.from_json is not None:
        report = json.loads(args.from_json.read_text())
        args.markdown.write_text(markdown(report))
        args.markdown.with_suffix(".json").write_text(json.dumps(report, indent=2) + "\n")
        return 0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    run = open_run(args.data, args.duration)
    t0 = time.perf_counter()
    graph = build_graph(run, GraphConfig())
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
    }

    # the long run first: its memory slope is then not hidden by pages earlier solves freed
    long = None
    if args.copies > 1:
        result, cpu, samples = online_profile(replay_graph(graph, args.copies), DEFAULT_LAG)
        long = online_summary(result, cpu, samples, run, None)
        long["copies"] = args.copies
        del result
        print("long run", json.dumps(long), flush=True)

    # batch: graphloc vs GTSAM alone, same graph, same process
    c0 = time.process_time()
    batch = solve(graph, "batch")
    batch_cpu = time.process_time() - c0
    metrics = evaluate(batch, run)
    batch_ate = {
        n: e["batch"]["ate_rmse"]
        for n, e in metrics["per_robot"].items()
        if isinstance(e.get("batch"), dict) and "ate_rmse" in e["batch"]
    }
    alone = gtsam_only_batch(graph)
    report["batch"] = {
        "graphloc_wall_s": batch.wall_s,
        "graphloc_cpu_s": batch_cpu,
        "gtsam_only": alone,
        "ratio_wall": batch.wall_s / alone["wall_s"],
        "ratio_cpu": batch_cpu / alone["cpu_s"],
        "ate_rmse_m": batch_ate,
        "realtime_factor": metrics["realtime_factor"],
    }
    print("batch", json.dumps(report["batch"]), flush=True)

    report["online"] = {}
    for lag in (float(x) for x in args.lags.split(",")):
        result, cpu, samples = online_profile(graph, lag or None)
        summary = online_summary(result, cpu, samples, run, batch_ate)
        report["online"][f"{lag:g}"] = summary
        print("online lag", lag, json.dumps(summary), flush=True)

    # the default lag at smaller relinearization thresholds: ATE against CPU
    report["online_relinearize"] = {}
    for thr in (float(x) for x in args.relinearize.split(",") if x):
        res, cpu, samples = online_profile(graph, DEFAULT_LAG, relinearize_threshold=thr)
        report["online_relinearize"][f"{thr:g}"] = online_summary(res, cpu, samples, run, batch_ate)
        print("relinearize", thr, json.dumps(report["online_relinearize"][f"{thr:g}"]), flush=True)

    # the default lag with other marginalization batch sizes: latency trend against CPU
    report["online_marginalize_every"] = {}
    for every in (float(x) for x in args.marginalize_every.split(",") if x):
        res, cpu, samples = online_profile(graph, DEFAULT_LAG, marginalize_every=every)
        summary = online_summary(res, cpu, samples, run, batch_ate)
        report["online_marginalize_every"][f"{every:g}"] = summary
        print("marginalize every", every, json.dumps(summary), flush=True)

    # what-if: the known-landmark anchors folded into unary factors on the poses
    folded = known_landmarks_unary(graph)
    c0 = time.process_time()
    fbatch = solve(folded, "batch")
    fmetrics = evaluate(fbatch, run)
    report["unary_landmarks"] = {
        "counts": folded.counts,
        "batch_cpu_s": time.process_time() - c0,
        "batch_ate_rmse_m": {
            n: e["batch"]["ate_rmse"]
            for n, e in fmetrics["per_robot"].items()
            if isinstance(e.get("batch"), dict) and "ate_rmse" in e["batch"]
        },
        "online": online_summary(*online_profile(folded, DEFAULT_LAG), run, batch_ate),
    }
    del folded, fbatch
    print("unary landmarks", json.dumps(report["unary_landmarks"], default=str), flush=True)

    base = report["online"].get(f"{DEFAULT_LAG:g}")
    if long is not None and base:
        long["p95_latency_over_single_run"] = long["latency_ms"]["p95"] / base["latency_ms"]["p95"]
        long["p95_cpu_over_single_run"] = (
            long["trend"]["cpu_p95_last10_ms"] / base["trend"]["cpu_p95_last10_ms"]
        )
        report["long_run"] = long

    report["rss_mb_end"] = rss_mb()
    report["load_average_at_end"] = os.getloadavg()
    path = out / "bench_scale.json"
    path.write_text(json.dumps(report, indent=2, default=str) + "\n")
    print(f"wrote {path}")
    if args.markdown is not None:  # the doc and its JSON side by side
        args.markdown.write_text(markdown(report))
        args.markdown.with_suffix(".json").write_text(path.read_text())
        print(f"wrote {args.markdown} and its JSON")
    return 0


def _num(x, fmt: str = ".2f") -> str:
    return "-" if x is None else format(x, fmt)


def markdown(r: dict) -> str:
    b = r["batch"]
    lines = [
        "# Online and batch at scale (issue 15)",
        "",
        f"Generated by `scripts/bench_scale.py` from `bench_scale.json` ({r['run']}, "
        f"{r['duration_s']:.0f} s, {r['counts']['poses']} poses, "
        f"{r['counts']['landmark_anchors']} landmark anchors, {r['counts']['steps']} steps; "
        f"{r['cpu_count']} cores, load average {r['load_average_at_start'][0]:.1f} at the start "
        f"and {r['load_average_at_end'][0]:.1f} at the end: wall times are of a shared machine, "
        "CPU times are this process's / this thread's).",
        "",
        "## Batch: graphloc vs GTSAM alone on the same graph",
        "",
        "| | wall [s] | CPU [s] | LM iterations |",
        "|---|---|---|---|",
        f"| graphloc `solve(graph, 'batch')` | {b['graphloc_wall_s']:.2f} | "
        f"{b['graphloc_cpu_s']:.2f} | |",
        f"| GTSAM `LevenbergMarquardtOptimizer.optimize()` | {b['gtsam_only']['wall_s']:.2f} | "
        f"{b['gtsam_only']['cpu_s']:.2f} | {b['gtsam_only']['iterations']} |",
        f"| ratio (target <= 1.5) | {b['ratio_wall']:.2f} | {b['ratio_cpu']:.2f} | |",
        "",
        "For reference only (another graph, another machine): CORA's published notes time GTSAM "
        "on a comparable MRCLAM 6 graph (11k poses, range-aided SLAM, one core) at about 7 s.",
        "",
        "## Online: full iSAM2 and fixed lags",
        "",
        f"Fixed lags marginalize every {r['marginalize_every_s']:g} s; the default lag is "
        f"{r['default_lag_s']:g} s (`graphloc online` without `--lag`). Targets (issue 15): p95 "
        "ratio <= 1.5, slowest step < 30 ms CPU, ATE / batch <= 1.10 per robot, real time > 100x.",
        "",
        "| lag [s] | p95 CPU first / last 10 % [ms] | ratio | slowest step CPU [ms] | "
        "p95 wall [ms] | variables at end | real time x (wall / CPU) | max ATE / batch | "
        "dropped |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for lag, o in r["online"].items():
        t = o["trend"]
        worst = max(o["ate_over_batch"].values()) if o.get("ate_over_batch") else float("nan")
        lines.append(
            f"| {'full' if lag == '0' else lag} | {t['cpu_p95_first10_ms']:.2f} / "
            f"{t['cpu_p95_last10_ms']:.2f} | {t['cpu_p95_last_over_first']:.2f} | "
            f"{t['cpu_max_ms']:.1f} | {o['latency_ms']['p95']:.2f} | {t['variables_end']} | "
            f"{o['realtime_factor']:.0f} / {o['realtime_factor_cpu']:.0f} | {worst:.3f} | "
            f"{sum(o['dropped_across_lag'].values())} |"
        )
    lines += [
        "",
        "ATE RMSE per robot [m] (SE(2)-aligned):",
        "",
        "| robot | batch | " + " | ".join(f"online lag {k}" for k in r["online"]) + " |",
        "|---|---|" + "---|" * len(r["online"]),
    ]
    for name, a in b["ate_rmse_m"].items():
        lines.append(
            f"| {name} | {a:.4f} | "
            + " | ".join(
                f"{o['ate_rmse_m'].get(name, float('nan')):.4f}" for o in r["online"].values()
            )
            + " |"
        )
    if r.get("online_relinearize"):
        lines += [
            "",
            f"## Relinearization at the default lag ({r['default_lag_s']:g} s)",
            "",
            "iSAM2 relinearizes a variable whose update exceeds the threshold (the run's own: "
            f"{r['relinearize_threshold_default']:g}, from its precision); a marginalized "
            "variable's factors stay linearized where they were when it left.",
            "",
            "| relinearize threshold | CPU [s] | real time x (CPU) | p95 CPU last 10 % [ms] | "
            "slowest step CPU [ms] | "
            + " | ".join(f"{n} ATE / batch" for n in b["ate_rmse_m"])
            + " |",
            "|---|---|---|---|---|" + "---|" * len(b["ate_rmse_m"]),
        ]
        rows = {f"{r['relinearize_threshold_default']:g}": r["online"][f"{r['default_lag_s']:g}"]}
        rows.update(r["online_relinearize"])
        for thr, o in rows.items():
            t = o["trend"]
            lines.append(
                f"| {thr} | {o['cpu_s']:.1f} | {o['realtime_factor_cpu']:.0f} | "
                f"{t['cpu_p95_last10_ms']:.2f} | {t['cpu_max_ms']:.1f} | "
                + " | ".join(
                    f"{o['ate_over_batch'].get(n, float('nan')):.3f}" for n in b["ate_rmse_m"]
                )
                + " |"
            )
    if r.get("online_marginalize_every"):
        lines += _marginalize_every_section(r)
    if "unary_landmarks" in r:
        u = r["unary_landmarks"]
        o, t = u["online"], u["online"]["trend"]
        worst = max(o["ate_over_batch"].values())
        lines += [
            "",
            "## What-if: known landmarks as unary factors (not the graph `build_graph` makes)",
            "",
            f"The {u['counts']['landmark_anchors_folded']} known-landmark anchors (a Point3 "
            "variable, its prior and one range-bearing factor each) folded into one "
            "`KnownLandmarkFactorPose3` on the observing pose "
            "(`graphloc.factors.range_bearing.known_landmark_factor_3d`, "
            "`graphloc.experiments.scale.known_landmarks_unary`); same run, same process.",
            "",
            f"- online, lag {o['lag_s']:g} s: p95 CPU first / last 10 % "
            f"{t['cpu_p95_first10_ms']:.2f} / {t['cpu_p95_last10_ms']:.2f} ms, slowest step CPU "
            f"{t['cpu_max_ms']:.1f} ms, variables at end {t['variables_end']}, real time "
            f"x{o['realtime_factor']:.0f} (wall) / x{o['realtime_factor_cpu']:.0f} (CPU), "
            f"max ATE / batch {worst:.3f} (against the anchors' batch);",
            f"- batch of this graph: CPU {u['batch_cpu_s']:.1f} s;",
            "",
            "| robot | batch (anchors) | batch (unary) | online lag "
            f"{o['lag_s']:g} (unary) | online / batch (anchors) |",
            "|---|---|---|---|---|",
        ]
        for name, a in b["ate_rmse_m"].items():
            lines.append(
                f"| {name} | {a:.4f} | {u['batch_ate_rmse_m'].get(name, float('nan')):.4f} | "
                f"{o['ate_rmse_m'].get(name, float('nan')):.4f} | "
                f"{o['ate_over_batch'].get(name, float('nan')):.3f} |"
            )
    if "long_run" in r:
        o = r["long_run"]
        t = o["trend"]
        mem = _num(o["memory_mb_per_1000_steps"])
        lines += [
            "",
            (
                f"## Long run: the run replayed {o['copies']} times (shifted clock), "
                f"lag {o['lag_s']:g} s"
            ),
            "",
            (
                f"- steps: {o['steps']}; p95 CPU first / last 10 %: "
                f"{t['cpu_p95_first10_ms']:.2f} / "
                f"{t['cpu_p95_last10_ms']:.2f} ms (ratio {t['cpu_p95_last_over_first']:.2f}); "
                f"slowest step CPU {t['cpu_max_ms']:.1f} ms;"
            ),
            (
                f"- p95 wall latency {o['latency_ms']['p95']:.2f} ms, "
                f"{_num(o.get('p95_latency_over_single_run'))}x the single run's; "
                "last-10 % p95 CPU "
                f"{_num(o.get('p95_cpu_over_single_run'))}x the single run's;"
            ),
            f"- variables held at the end: {t['variables_end']} (max {t['variables_max']});",
            (
                f"- resident memory slope: {mem} MB per 1,000 steps, "
                f"{o['rss_mb_end']:.0f} MB at the end (the session keeps no steps, "
                "`SessionConfig.keep_steps` False; what still grows is the marginalized "
                "variables' last estimates -- the final trajectory --, the per-step log and "
                "iSAM2's emptied factor slots);"
            ),
            (
                f"- real time x{o['realtime_factor']:.0f} (wall), "
                f"x{o['realtime_factor_cpu']:.0f} (CPU)."
            ),
        ]
    lines += ["", "## How", "", *NOTES]
    lines.append("")
    return "\n".join(lines)


def _marginalize_every_section(r: dict) -> list:
    """The default lag at each marginalization batch size: CPU, p95 ratio, and the same ratio
    over the steps that did not marginalize (`graphloc.experiments.scale.marginalization_split`)."""
    rows = {f"{r['marginalize_every_s']:g}": r["online"][f"{r['default_lag_s']:g}"]}
    rows.update(r["online_marginalize_every"])
    lines = [
        "",
        f"## Marginalization batch size at the default lag ({r['default_lag_s']:g} s)",
        "",
        "Old variables leave the window in batches of `marginalize_every` seconds; a step that "
        "marginalizes also pays the full back-substitution of the window and "
        "`marginalizeLeaves`. The p95 of a tenth lands on marginalizing steps when they are "
        "more than 5 % of its steps; the first tenth has fewer (no marginalization while the "
        "window fills), so the p95 ratio mixes the batch size with growth. The last columns "
        "leave the marginalizing steps out (thread CPU time of each step).",
        "",
        "| marginalize every [s] | CPU [s] | real time x (CPU) | p95 CPU first / last 10 % [ms] "
        "| ratio | marginalizing steps first / last 10 % | p95 CPU of the other steps first / "
        "last 10 % [ms] | ratio | slowest step CPU [ms] | max ATE / batch |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for every, o in sorted(rows.items(), key=lambda kv: float(kv[0])):
        t, m = o["trend"], o["marginalization"]
        worst = max(o["ate_over_batch"].values())
        lines.append(
            f"| {every} | {o['cpu_s']:.1f} | {o['realtime_factor_cpu']:.0f} | "
            f"{t['cpu_p95_first10_ms']:.2f} / {t['cpu_p95_last10_ms']:.2f} | "
            f"{t['cpu_p95_last_over_first']:.2f} | {100 * m['share_first10']:.1f} % / "
            f"{100 * m['share_last10']:.1f} % | {m['cpu_p95_first10_other_ms']:.2f} / "
            f"{m['cpu_p95_last10_other_ms']:.2f} | {m['cpu_p95_other_last_over_first']:.2f} | "
            f"{t['cpu_max_ms']:.1f} | {worst:.3f} |"
        )
    return lines


NOTES = [
    "- Fixed lag (`graphloc.session.SessionConfig.lag`, `marginalize_every`): iSAM2 with",
    "  `ISAM2::marginalizeLeaves`. Variables are stamped with their add time rounded down to",
    "  a multiple of `marginalize_every`; every update passes iSAM2 a constrained ordering with",
    "  one group per live stamp, oldest first, so the oldest stamps are always leaves of the",
    "  Bayes tree and leave by `marginalizeLeaves` alone. GTSAM's IncrementalFixedLagSmoother",
    "  (used before) re-orders and re-eliminates the path from the marginalized cliques to the",
    "  root -- on this team graph about the whole window -- at every marginalization: its",
    "  slowest steps were those, and they grew with the window, so a longer window (better",
    "  ATE) cost a slower worst step. Variables are not re-stamped when later factors touch",
    "  them, so long-lived ones (static robots, SLAM landmarks) would leave the window: such",
    "  runs default to full smoothing (`graphloc.pipelines.team_graph.default_lag`).",
    "- A variable leaving the window keeps the estimate of a full back-substitution",
    "  (`ISAM2::calculateBestEstimate`, once per marginalization), not iSAM2's own, which stops",
    "  where the solution changes less than the wildfire threshold and could freeze a stale value.",
    "- The team graph's sessions keep no steps (`SessionConfig.keep_steps` False: nothing to",
    "  `save`; `online --checkpoint` replays the graph instead), so a long run holds only the",
    "  window, the marginalized estimates and the per-step log.",
    "- Real time x (CPU) is the run's duration over the solve's CPU time; on a machine shared",
    "  by other jobs (the load averages above) the wall-clock factor is about that times",
    "  cores / load, whatever the solver does.",
    "- Memory is measured on the long run only, which runs first in the process (later solves",
    "  reuse pages earlier ones freed, which hides their growth).",
    "- The first tenth of a fixed-lag run includes the window filling up, so its p95 is lower",
    "  than the steady state's; the long run's last tenth against the single run's last tenth",
    "  is the comparison of steady states.",
    "- Resume replays the iSAM2 updates from the log (the checkpoint holds the position and a",
    "  fingerprint, no Bayes tree), so it is identical by construction but not cheaper than the",
    "  steps it replays.",
    "- The GTSAM-only time is `LevenbergMarquardtOptimizer.optimize()` on the same factors and",
    "  initial values with the same parameters; graphloc's time includes adding the steps to the",
    "  `Session`, its iteration-by-iteration LM loop (progress) and reading the estimate out.",
    "- Full iSAM2 (lag 0) grows per step on GTSAM 4.3 also on a plain Pose2 chain: "
    "[gtsam_isam2_chain.md](gtsam_isam2_chain.md).",
]
