"""Reproduce seed 004's tables side by side (paper | seed baseline | graphloc); see
graphloc.experiments.seed004.

    .venv/bin/python scripts/repro_seed004.py [--quick] [--out DIR]
"""

from graphloc.experiments.seed004 import main

if __name__ == "__main__":
    raise SystemExit(main())
