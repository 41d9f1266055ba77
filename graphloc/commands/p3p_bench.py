"""`graphloc p3p-bench --out DIR [--n N] [--seed S]`: time the batched P3P solvers against
per-instance loops over cv2.solveP3P and poselib.p3p on the same random instances; writes
p3p_bench.json, p3p_bench.md and p3p_bench.png to DIR."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

from graphloc.commands.common import progress
from graphloc.config import add_config_arguments, check, config_from_args
from graphloc.exitcodes import OK

HELP = (
    "benchmark the batched P3P solvers against cv2.solveP3P / poselib.p3p loops "
    "(JSON, markdown, PNG)"
)


@dataclass(frozen=True)
class P3PBenchOptions:
    """The options of `graphloc p3p-bench` (command line and `--config FILE.toml`)."""

    n: int = field(default=100_000, metadata={"help": "number of random instances"})
    seed: int = field(default=0, metadata={"help": "random seed of the instances"})

    def __post_init__(self):
        check(self, integer={"n": (1, 10_000_000), "seed": (0, 2**32 - 1)})


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, type=Path, help="output directory")
    parser.add_argument("--config", type=Path, help="TOML file with any of the options below")
    add_config_arguments(parser, P3PBenchOptions)


def run(args: argparse.Namespace) -> int:
    # imported here, not at the top: the benchmark loads matplotlib, which `graphloc --help`
    # does not need
    from graphloc.experiments.p3p_bench import markdown_table, run_p3p_benchmark

    opts = config_from_args(P3PBenchOptions, args)
    result = run_p3p_benchmark(args.out, n=opts.n, seed=opts.seed, progress=progress(args))
    print(markdown_table(result))
    return OK
