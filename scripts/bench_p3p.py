#!/usr/bin/env python
"""P3P speed/recovery benchmark (same as `graphloc p3p-bench`): batched graphloc solvers vs
per-instance Python loops over cv2.solveP3P (P3P, AP3P) and poselib.p3p on the same instances.

    .venv/bin/python scripts/bench_p3p.py --out out/bench_p3p [--n 100000] [--seed 0]
"""

import sys

from graphloc.cli import main

if __name__ == "__main__":
    sys.exit(main(["p3p-bench", *sys.argv[1:]]))
