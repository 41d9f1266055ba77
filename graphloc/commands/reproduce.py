"""`graphloc reproduce TABLE [--quick] [--out DIR]`: recompute one seed table
(graphloc.experiments.reproduce, the route scripts/make_results.py takes too) and print it as
markdown; JSON goes to DIR/<table>.json. The trials run on the executor's backend
(`--backend local|ray`, `--workers N`, `--address auto|HOST:PORT`: graphloc.executor); the
table is cached under DIR/.cache by the content hash of (table, run sizes, code version), so a
re-run prints it without recomputing (`--no-cache` recomputes). Full-size runs with plots:
scripts/repro_seed000.py, scripts/repro_seed004.py, scripts/make_results.py."""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

from graphloc.commands.common import progress
from graphloc.config import add_config_arguments, check, config_from_args
from graphloc.executor import BACKENDS
from graphloc.experiments import TABLES
from graphloc.exitcodes import OK
from graphloc.structured import dumps_json

HELP = "reproduce a seed table: seed000-table1/2/3, seed004-table1, seed001-exp1"


@dataclass(frozen=True)
class ReproduceOptions:
    """The options of `graphloc reproduce` (command line and `--config FILE.toml`)."""

    quick: bool = field(
        default=False, metadata={"help": "CI size (graphloc.experiments.sizes.QUICK)"}
    )
    workers: int = field(default=2, metadata={"help": "trials in flight"})
    backend: str = field(default="local", metadata={"help": f"trials on: {', '.join(BACKENDS)}"})
    address: str | None = field(
        default=None, metadata={"help": "--backend ray: 'auto' or HOST:PORT of a cluster"}
    )
    cache: bool = field(
        default=True, metadata={"help": "print a cached table (--no-cache recomputes)"}
    )

    def __post_init__(self):
        check(self, integer={"workers": (1, 256)}, choices={"backend": BACKENDS})


def add_arguments(parser) -> None:
    parser.add_argument("table", choices=TABLES)
    parser.add_argument("--out", type=Path, default=Path("out/reproduce"))
    parser.add_argument("--config", type=Path, help="TOML file with any of the options below")
    add_config_arguments(parser, ReproduceOptions)


def run(args) -> int:
    # imported here, not at the top: the experiments load matplotlib, GTSAM trials and the
    # simulators, which `graphloc --help` does not need
    from graphloc.executor import ResultCache, default_backend
    from graphloc.experiments.reproduce import reproduce

    opts = config_from_args(ReproduceOptions, args)
    args.out.mkdir(parents=True, exist_ok=True)
    cache = ResultCache(args.out / ".cache") if opts.cache else None
    with default_backend(opts.backend, opts.address, opts.workers):
        result, md, cached = reproduce(
            args.table, opts.quick, opts.workers, args.out, cache=cache, progress=progress(args)
        )
    if cached:
        print(f"(cached: {args.out / '.cache'}; --no-cache recomputes)", file=sys.stderr)
    if result is not None:
        (args.out / f"{args.table}.json").write_text(dumps_json(result, indent=2, default=float))
    print(md)
    return OK
