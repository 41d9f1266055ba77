"""Reproduce seed 001 experiment 1 in simulation; see benchmarks.seed001.

.venv/bin/python scripts/repro_seed001.py [--frames1 300 --frames2 200 --out out/seed001]
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.seed001 import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main())
