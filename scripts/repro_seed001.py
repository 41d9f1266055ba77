"""Reproduce seed 001 experiment 1 in simulation; see graphloc.experiments.seed001.

.venv/bin/python scripts/repro_seed001.py [--frames1 300 --frames2 200 --out out/seed001]
"""

from graphloc.experiments.seed001 import main

if __name__ == "__main__":
    raise SystemExit(main())
