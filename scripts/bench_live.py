"""The live API's per-step latency and CPU against `graphloc online` on MRCLAM Dataset6 (issue
50), JSON with the ratios of one run. Thin wrapper: the code is benchmarks.bench_live (its
options: `--help`)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.bench_live import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
