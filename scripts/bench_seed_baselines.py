"""Issue 20: the seeds' own methods under readings of the seeds' setups, and graphloc at the
reproducing setting; see benchmarks.seed_baselines_report.

    .venv/bin/python scripts/bench_seed_baselines.py [--quick] [--workers 2] [--out DIR]
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.seed_baselines_report import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main())
