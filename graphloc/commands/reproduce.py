"""`graphloc reproduce TABLE [--quick] [--out DIR]`: recompute one seed table
(graphloc.experiments.reproduce, the route scripts/make_results.py takes too) and print it as
markdown; JSON goes to DIR/<table>.json. The trials run on the executor's backend
(`--backend local|ray`, `--workers N`, `--address auto|HOST:PORT`: graphloc.executor); the
table is cached under DIR/.cache by the content hash of (table, run sizes, code version), so a
re-run prints it without recomputing (`--no-cache` recomputes). Full-size runs with plots:
scripts/repro_seed000.py, scripts/repro_seed004.py, scripts/make_results.py."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from graphloc.executor import BACKENDS
from graphloc.experiments import TABLES
from graphloc.exitcodes import OK

HELP = "reproduce a seed table: seed000-table1/2/3, seed004-table1, seed001-exp1"


def add_arguments(parser) -> None:
    parser.add_argument("table", choices=TABLES)
    parser.add_argument(
        "--quick", action="store_true", help="CI size (graphloc.experiments.sizes.QUICK)"
    )
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--backend", choices=BACKENDS, default="local", help="trials on")
    parser.add_argument("--address", help="--backend ray: 'auto' or HOST:PORT of a cluster")
    parser.add_argument("--no-cache", action="store_true", help="recompute a cached table")
    parser.add_argument("--out", type=Path, default=Path("out/reproduce"))


def run(args) -> int:
    # imported here, not at the top: the experiments load matplotlib, GTSAM trials and the
    # simulators, which `graphloc --help` does not need
    from graphloc.executor import ResultCache, default_backend
    from graphloc.experiments.reproduce import reproduce

    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    args.out.mkdir(parents=True, exist_ok=True)
    cache = None if args.no_cache else ResultCache(args.out / ".cache")
    with default_backend(args.backend, args.address, args.workers):
        result, md, cached = reproduce(args.table, args.quick, args.workers, args.out, cache=cache)
    if cached:
        print(f"(cached: {args.out / '.cache'}; --no-cache recomputes)", file=sys.stderr)
    if result is not None:
        (args.out / f"{args.table}.json").write_text(json.dumps(result, indent=2, default=float))
    print(md)
    return OK
