"""The one route to the seeds' tables: scripts/reproduce.py TABLE (`main`, one table printed as
markdown, cached) and scripts/make_results.py (`make_results`, docs/results.md) both call this
module, at the run sizes of benchmarks.sizes.

- seed000-table1/2/3: seed 000 (000_05137a0a9c449be3.txt) Tables I-III,
  benchmarks.seed000;
- seed004-table1: seed 004 (004_fa12d1d18dcbd0db.txt) Table 1, benchmarks.seed004;
- seed001-exp1: seed 001 (001_0f8f8dae37ce6b79.txt) experiment 1, benchmarks.seed001.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import asdict
from pathlib import Path

from graphloc.datasets.feng_deterministic import TableIConfig
from benchmarks.trials import default_backend
from graphloc.executor import BACKENDS, ResultCache, content_hash
from graphloc.structured import dumps_json
from benchmarks import TABLES, seed000, seed001, seed004
from benchmarks.hypotheses import TableIIIConfig
from benchmarks.seed_baselines_report import DOC_JSON
from benchmarks.render import render
from benchmarks.sizes import RunSizes, run_sizes


def seed001_result(out_dir: Path, sizes: RunSizes) -> dict:
    """Seed 001 experiment 1 (rendered frames; writes its JSON with every frame and its PNG to
    out_dir); returns the paper's numbers, the summary per run and variant and the config."""
    result = seed001.reproduce(
        out_dir, frames1=sizes.seed001_frames1, frames2=sizes.seed001_frames2
    )
    return {key: result[key] for key in ("paper", "summary", "config", "seconds")}


def reproduce(
    table: str,
    quick: bool,
    workers: int,
    out: Path,
    progress: bool = True,
    cache: ResultCache | None = None,
) -> tuple[dict, bool]:
    """One table: (its JSON-ready result, the entry docs/results.json holds for it; whether it
    came from `cache`). The trials run on the executor's default backend
    (`benchmarks.trials.default_backend`); the cache key is the content hash of (table, run
    sizes, graphloc's code version): the worker count and the backend do not change the
    numbers."""
    if table not in TABLES:
        raise ValueError(f"unknown table {table!r}; choose from {', '.join(TABLES)}")
    sizes = run_sizes(quick)
    key = content_hash([], {"table": table, "sizes": asdict(sizes)})
    if cache is not None and table == "seed001-exp1" and not (out / "seed001").is_dir():
        cache.discard(key)  # its JSON and PNG live under out/seed001
    hit = cache.get(key) if cache is not None else None
    if hit is not None and hit.get("result") is not None:
        return hit["result"], True
    result = json_ready(_compute(table, sizes, workers, out, progress))
    if cache is not None:
        cache.put(key, {"result": result})
    return result, False


def json_ready(result: dict) -> dict:
    """`result` as its JSON reads back (tuples lists, numpy scalars floats): what a cache hit
    and docs/results.json return."""
    return json.loads(dumps_json(result, default=float))


def _compute(table: str, sizes: RunSizes, workers: int, out: Path, progress: bool) -> dict:
    if table == "seed001-exp1":
        return seed001_result(out / "seed001", sizes)
    if table == "seed000-table1":
        return seed000.table_i(TableIConfig(trials=sizes.table1_trials, workers=workers), progress)
    if table == "seed000-table2":  # times its own trials and updates, in one process
        return seed000.table_ii(samples=sizes.table2_samples)
    if table == "seed000-table3":
        return seed000.table_iii(TableIIIConfig(runs=sizes.table3_runs, workers=workers), progress)
    return seed004.seed004_table_1(
        runs=sizes.seed004_runs, frames=sizes.seed004_frames, workers=workers, progress=progress
    )


def write_results(results: Path, doc: dict) -> None:
    """docs/results.json (`doc`: the run and one entry per table) beside `results`, and
    `results` (docs/results.md) rendered from that JSON as written (benchmarks.render.results;
    its last section from docs/results_seed_baselines.json), as scripts/render_docs.py renders
    it."""
    text = dumps_json(doc, indent=1) + "\n"
    results.parent.mkdir(parents=True, exist_ok=True)
    results.with_suffix(".json").write_text(text)
    results.write_text(render("results", json.loads(text), json.loads(DOC_JSON.read_text())))


def make_results(
    out: Path,
    results: Path,
    quick: bool,
    workers: int,
    skip_seed001: bool = False,
    backend: str = "local",
    address: str | None = None,
) -> float:
    """docs/results.md and docs/results.json beside it (`write_results`): every seed table with
    its plots and JSON under `out`, the trials on the executor's `backend`
    (graphloc.executor); returns the wall time [s]."""
    t0 = time.perf_counter()
    sizes = run_sizes(quick)
    with default_backend(backend, address, workers):
        s000 = seed000.run(out / "seed000", sizes, workers)
        tables = {
            "seed000-table1": s000["table_i"],
            "seed000-table2": s000["table_ii"],
            "seed000-table3": s000["table_iii"],
            "seed004-table1": seed004.run(out / "seed004", sizes, workers),
        }
    if not skip_seed001:
        tables["seed001-exp1"] = seed001_result(out / "seed001", sizes)
    seconds = time.perf_counter() - t0
    run = {
        "command": f"scripts/make_results.py{' --quick' if quick else ''}",
        "seconds": seconds,
        "cores": os.cpu_count(),
        "processor": platform.processor() or platform.machine(),
        "workers": workers,
        "backend": backend,
        "out": str(out),
    }
    sections = {name: {"command": None, "result": json_ready(r)} for name, r in tables.items()}
    write_results(results, {"run": run, "sections": sections})
    return seconds


def main(argv=None) -> int:
    """`scripts/reproduce.py TABLE [--quick] [--out DIR] [--results docs/results.md]`:
    recompute one seed table and print it as markdown; its JSON goes to DIR/<table>.json and,
    with --results, replaces the table's entry in the JSON beside that doc (the doc re-rendered,
    the entry naming this command). The trials run on the executor's backend (`--backend
    local|ray`, `--workers N`, `--address auto|HOST:PORT`: graphloc.executor); the table is
    cached under DIR/.cache by the content hash of (table, run sizes, code version), so a re-run
    prints it without recomputing (`--no-cache` recomputes)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = argparse.ArgumentParser(description="reproduce a seed table: " + ", ".join(TABLES))
    parser.add_argument("table", choices=TABLES)
    parser.add_argument("--out", type=Path, default=Path("out/reproduce"))
    parser.add_argument("--quick", action="store_true", help="CI size (benchmarks.sizes.QUICK)")
    parser.add_argument("--workers", type=int, default=2, help="trials in flight")
    parser.add_argument("--backend", choices=BACKENDS, default="local", help="trials on")
    parser.add_argument("--address", help="--backend ray: 'auto' or HOST:PORT of a cluster")
    parser.add_argument("--no-cache", action="store_true", help="recompute a cached table")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    parser.add_argument(
        "--results", type=Path, help="a doc of scripts/make_results.py whose table entry to replace"
    )
    args = parser.parse_args(argv)
    if not 1 <= args.workers <= 256:
        parser.error(f"--workers must be in [1, 256], got {args.workers}")
    if args.results is not None and not args.results.with_suffix(".json").is_file():
        parser.error(f"no {args.results.with_suffix('.json')} to replace the entry of")
    args.out.mkdir(parents=True, exist_ok=True)
    cache = None if args.no_cache else ResultCache(args.out / ".cache")
    with default_backend(args.backend, args.address, args.workers):
        result, cached = reproduce(
            args.table, args.quick, args.workers, args.out, not args.no_progress, cache
        )
    if cached:
        print(f"(cached: {args.out / '.cache'}; --no-cache recomputes)", file=sys.stderr)
    (args.out / f"{args.table}.json").write_text(dumps_json(result, indent=2))
    entry = {"command": " ".join(["scripts/reproduce.py", *argv]), "result": result}
    if args.results is not None:
        doc = json.loads(args.results.with_suffix(".json").read_text())
        doc["sections"][args.table] = entry
        doc["sections"] = {
            name: doc["sections"][name] for name in TABLES if name in doc["sections"]
        }
        write_results(args.results, doc)
    print(render("results_section", args.table, {"result": result}))
    return 0
