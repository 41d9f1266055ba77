"""Seed 003 on the rendered `crawler-pair` scenario: the seed's EKF vs graphloc batch / online
and the ablations; see benchmarks.seed003.

    .venv/bin/python scripts/bench_seed003.py [--trials 16] [--seed-offset 0] --out DIR [--doc MD]
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.seed003 import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main())
