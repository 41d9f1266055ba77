"""Reproduce seed 000's tables side by side (paper | seed baseline | graphloc); see
benchmarks.seed000.

    .venv/bin/python scripts/repro_seed000.py [--quick] [--out DIR]
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.seed000 import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main())
