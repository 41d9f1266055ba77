#!/usr/bin/env python
"""P3P speed/recovery benchmark (`make bench-p3p`): batched graphloc solvers vs per-instance
Python loops over cv2.solveP3P (P3P, AP3P) and poselib.p3p on the same instances; writes
p3p_bench.json, p3p_bench.md and p3p_bench.png to --out (benchmarks.p3p_bench).

    .venv/bin/python scripts/bench_p3p.py --out out/bench_p3p [--n 100000] [--seed 0]
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.p3p_bench import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
