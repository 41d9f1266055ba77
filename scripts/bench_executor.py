"""Throughput of graphloc.executor's two backends on many runs (issue 19): N simulated
feng-probabilistic runs (seed 000 Sec. VI-B; one log per seed) go through the front door,
`graphloc online RUN1 ... RUNN --backend B --workers W`, for W = 1, 2 on the local process pool
and on a local Ray instance, all in the same process and on the same runs; then the last
configuration again over the same output directory (every run from the cache).

Reported (JSON, markdown, PNG) in OUT: wall time and runs per minute per configuration, the median
task time, Ray's overhead against the local pool at equal workers (wall time ratio - 1), the
speed-up from 1 to 2 workers, the cached re-run's wall time, Ray's start-up time (kept out of
the throughput: a cluster is started once), and whether every configuration gave identical
numbers (per-run rows without timings, and every TUM file byte for byte). The markdown is
rendered from the JSON (benchmarks.render.executor); with --doc it goes there too, the JSON
beside it (docs/results_executor.{md,json}; `scripts/render_docs.py results_executor.md`
re-renders the doc from that JSON).

    nice -n 10 .venv/bin/python scripts/bench_executor.py --speed 0.02 --out out/bench_executor \
        --doc docs/results_executor.md

The benchmark drives the command line in-process (graphloc.cli.main); only its report needs
benchmarks/ (the checkout's, put on the path)."""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from graphloc.cli import main as graphloc_main
from graphloc.structured import dumps_json

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.markdown import write_report  # noqa: E402
from benchmarks.render import render  # noqa: E402
from benchmarks.trials import TrialExecutor, default_backend  # noqa: E402

CONFIGS = [("local", 1), ("local", 2), ("ray", 1), ("ray", 2)]
SCENARIO = "feng-probabilistic"


def _simulate(item: tuple[int, str, float]) -> str:
    seed, out, speed = item
    args = ["simulate", SCENARIO, "--out", out, "--seed", str(seed), "--speed", str(speed)]
    if graphloc_main(args) != 0:
        raise RuntimeError(f"graphloc simulate {SCENARIO} --seed {seed} failed")
    return out


def _results(out: Path) -> tuple[dict, dict]:
    rows = json.loads((out / "runs.json").read_text())["runs"]
    drop = ("seconds", "realtime_factor", "status", "path")
    table = {r["run"]: {k: v for k, v in r.items() if k not in drop} for r in rows}
    tum = {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*.tum"))}
    return table, tum


def _one(verb: str, runs: list[str], out: Path, backend: str, workers: int) -> dict:
    args = [verb, *runs, "--out", str(out), "--backend", backend, "--workers", str(workers)]
    t0 = time.perf_counter()
    code = graphloc_main([*args, "--no-progress"])
    wall = time.perf_counter() - t0
    rows = json.loads((out / "runs.json").read_text())["runs"]
    task = [r["seconds"] for r in rows if r["status"] != "cached"]
    return {
        "backend": backend,
        "workers": workers,
        "exit_code": code,
        "wall_s": wall,
        "runs_per_min": 60.0 * len(rows) / wall,
        "statuses": {s: sum(r["status"] == s for r in rows) for s in {r["status"] for r in rows}},
        "task_s_median": float(np.median(task)) if task else 0.0,
        "task_s_sum": float(np.sum(task)),
    }


def run(args: argparse.Namespace) -> dict:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    runs_dir = out / "runs"
    items = [
        (s, str(runs_dir / f"feng{s:03d}_v{args.speed:g}"), args.speed) for s in range(args.runs)
    ]
    todo = [it for it in items if not (Path(it[1]) / "manifest.json").is_file()]
    t0 = time.perf_counter()
    with TrialExecutor(2, progress=True) as ex:  # the set-up: simulated logs
        list(ex.imap(_simulate, todo, desc="simulate"))
    simulate_s = time.perf_counter() - t0
    runs = [it[1] for it in items]
    measured, outputs = [], {}
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    with default_backend("ray", workers=2):  # one local Ray instance (2 CPUs) for both W
        ray_start_s = time.perf_counter() - t0
        for repeat, (backend, workers) in args.order:
            target = out / f"{args.verb}_{backend}_{workers}"
            if target.exists():  # a fresh output directory: nothing cached
                shutil.rmtree(target)
            print(f"{args.verb}: {len(runs)} runs, backend {backend}, {workers} worker(s)")
            measured.append({**_one(args.verb, runs, target, backend, workers), "repeat": repeat})
            outputs[backend, workers, repeat] = _results(target)
        print("again over the last output directory: every run cached")
        cached = _one(args.verb, runs, target, backend, workers)
    reference = outputs[next(iter(outputs))]
    configs = [_mean(measured, b, w, len(runs)) for b, w in CONFIGS]
    by = {(m["backend"], m["workers"]): m for m in configs}
    result = {
        "benchmark": "executor",
        "command": args.command,
        "machine": {
            "cpus": os.cpu_count(),
            "processor": platform.processor() or platform.machine(),
        },
        "load_average_1_5_15_min": {"before": load_before, "after": os.getloadavg()},
        "verb": args.verb,
        "scenario": SCENARIO,
        "speed_m_per_s": args.speed,
        "runs": len(runs),
        "simulate_s": simulate_s,
        "ray_start_s": ray_start_s,
        "order": [[r, b, w] for r, (b, w) in args.order],
        "configs": configs,
        "measured": measured,
        "identical_results": all(o == reference for o in outputs.values()),
        "ray_overhead": {
            str(w): by["ray", w]["wall_s"] / by["local", w]["wall_s"] - 1.0 for w in (1, 2)
        },
        "speedup_2_workers": {b: by[b, 1]["wall_s"] / by[b, 2]["wall_s"] for b in ("local", "ray")},
        "cached_rerun": {**cached, "over_first_run": cached["wall_s"] / measured[-1]["wall_s"]},
    }
    result = json.loads(dumps_json(result))  # as the doc's JSON reads back
    report(result, out, args.doc)
    return result


def report(result: dict, out: Path, doc: Path | None) -> None:
    """OUT/bench_executor.{json,md,png}; with `doc` the markdown there too and the JSON beside
    it (the markdown: benchmarks.render.executor, from the JSON)."""
    text = render("executor", result, doc=doc.stem if doc else "bench_executor")
    write_report(out, "bench_executor", result, text, doc, rendered=result)
    plot(result, out / "bench_executor.png")


def _mean(measured: list[dict], backend: str, workers: int, runs: int) -> dict:
    """One configuration over its repeats: mean wall time, runs per minute from it."""
    ms = [m for m in measured if (m["backend"], m["workers"]) == (backend, workers)]
    wall = float(np.mean([m["wall_s"] for m in ms]))
    return {
        "backend": backend,
        "workers": workers,
        "wall_s": wall,
        "wall_s_each": [m["wall_s"] for m in ms],
        "runs_per_min": 60.0 * runs / wall,
        "task_s_median": float(np.median([m["task_s_median"] for m in ms])),
        "statuses": ms[-1]["statuses"],
    }


def plot(result: dict, path: Path) -> None:
    from graphloc.plots import plt

    labels = [f"{m['backend']}\n{m['workers']} worker(s)" for m in result["configs"]]
    labels.append("cached\nre-run")
    rates = [m["runs_per_min"] for m in result["configs"]]
    rates.append(result["cached_rerun"]["runs_per_min"])
    colors = ["tab:blue", "tab:blue", "tab:orange", "tab:orange", "tab:gray"]
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.bar(range(len(rates)), rates, color=colors)
    ax.set_xticks(range(len(rates)), labels)
    ax.set_yscale("log")
    ax.set_ylabel("runs per minute (log)")
    ax.set_title(f"graphloc {result['verb']} over {result['runs']} runs: executor backends")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/bench_executor"))
    parser.add_argument(
        "--doc", type=Path, help="also write the markdown here and its JSON beside it"
    )
    parser.add_argument("--runs", type=int, default=16, help="simulated runs (default 16)")
    parser.add_argument("--verb", choices=("smooth", "online"), default="online")
    parser.add_argument(
        "--repeats",
        type=int,
        choices=(1, 2),
        default=2,
        help="2: the configurations, then again in reverse order",
    )
    parser.add_argument(
        "--speed", type=float, default=0.1, help="climber speed [m/s]: slower = longer runs"
    )
    parser.add_argument(
        "--doc-only",
        action="store_true",
        help="rewrite the markdown, --doc and the PNG from OUT's JSON",
    )
    args = parser.parse_args(argv)
    if args.doc_only:
        report(json.loads((args.out / "bench_executor.json").read_text()), args.out, args.doc)
        return 0
    if args.runs < 2:
        raise SystemExit("--runs must be >= 2")
    args.order = [(0, c) for c in CONFIGS]
    args.order += [(1, c) for c in reversed(CONFIGS)] if args.repeats == 2 else []
    args.command = "scripts/bench_executor.py " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    r = run(args)
    print(
        json.dumps(
            {
                "identical_results": r["identical_results"],
                "runs_per_min": {
                    f"{m['backend']}_{m['workers']}": round(m["runs_per_min"], 2)
                    for m in r["configs"]
                },
                "ray_overhead": {k: round(v, 4) for k, v in r["ray_overhead"].items()},
                "cached_rerun_s": round(r["cached_rerun"]["wall_s"], 2),
            },
            indent=1,
        )
    )
    print(f"wrote {args.out / 'bench_executor.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
