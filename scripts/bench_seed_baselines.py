"""Issue 20: the seeds' own methods under readings of the seeds' setups, and graphloc at the
reproducing setting; see graphloc.experiments.seed_baselines_report.

    .venv/bin/python scripts/bench_seed_baselines.py [--quick] [--workers 2] [--out DIR]
"""

from graphloc.experiments.seed_baselines_report import main

if __name__ == "__main__":
    raise SystemExit(main())
