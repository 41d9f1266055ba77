"""HypothesisTracker vs the seeds' baselines on seed 000's probabilistic setup (Table III),
plus the long-run latency / memory test; see benchmarks.bench_hypotheses.

    .venv/bin/python scripts/bench_hypotheses.py [--quick] --out out/bench_hypotheses
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.bench_hypotheses import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main())
