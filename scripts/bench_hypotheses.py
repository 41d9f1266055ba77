"""HypothesisTracker vs the seeds' baselines on seed 000's probabilistic setup (Table III),
plus the long-run latency / memory test; see graphloc.experiments.bench_hypotheses.

    .venv/bin/python scripts/bench_hypotheses.py [--quick] --out out/bench_hypotheses
"""

from graphloc.experiments.bench_hypotheses import main

if __name__ == "__main__":
    raise SystemExit(main())
