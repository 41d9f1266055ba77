"""`graphloc p3p-bench --out DIR [--n N] [--seed S]`: time the batched P3P solvers against
per-instance loops over cv2.solveP3P and poselib.p3p on the same random instances."""

from __future__ import annotations

import argparse

from graphloc.exitcodes import OK

HELP = (
    "benchmark the batched P3P solvers against cv2.solveP3P / poselib.p3p loops "
    "(JSON, markdown, PNG)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument(
        "--n", type=int, default=100_000, help="number of random instances (default 100000)"
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed of the instances")


def run(args: argparse.Namespace) -> int:
    # imported here, not at the top: the benchmark loads matplotlib, which `graphloc --help`
    # does not need
    from graphloc.experiments.p3p_bench import markdown_table, run_p3p_benchmark

    if args.n < 1:
        raise ValueError(f"--n must be positive, got {args.n}")
    result = run_p3p_benchmark(args.out, n=args.n, seed=args.seed)
    print(markdown_table(result))
    print(f"wrote {args.out}/p3p_bench.json, p3p_bench.md, p3p_bench.png")
    return OK
