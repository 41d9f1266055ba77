"""Reproduce seed 000's tables side by side (paper | seed baseline | graphloc); see
graphloc.experiments.seed000.

    .venv/bin/python scripts/repro_seed000.py [--quick] [--out DIR]
"""

from graphloc.experiments.seed000 import main

if __name__ == "__main__":
    raise SystemExit(main())
