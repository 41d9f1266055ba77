"""Seed 003 on the rendered `crawler-pair` scenario: the seed's EKF vs graphloc batch / online
and the ablations; see graphloc.experiments.seed003.

    .venv/bin/python scripts/bench_seed003.py [--trials 16] [--seed-offset 0] --out DIR [--doc MD]
"""

from graphloc.experiments.seed003 import main

if __name__ == "__main__":
    raise SystemExit(main())
