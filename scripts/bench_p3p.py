#!/usr/bin/env python
"""P3P speed/recovery benchmark (same as `graphloc p3p-bench`): batched graphloc solvers vs
per-instance Python loops over cv2.solveP3P (P3P, AP3P) and poselib.p3p on the same instances.

    .venv/bin/python scripts/bench_p3p.py --out out/bench_p3p [--n 100000] [--seed 0]
"""

import argparse
import sys

from graphloc.commands import p3p_bench

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=p3p_bench.HELP)
    p3p_bench.add_arguments(parser)
    sys.exit(p3p_bench.run(parser.parse_args()))
