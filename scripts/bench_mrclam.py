"""MRCLAM benchmark: dead reckoning vs batch (LM) vs online (iSAM2) smoothing on a whole MRCLAM
dataset, with and without landmarks, plus cooperative SLAM (benchmarks.bench_mrclam;
`--help` lists the options)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.bench_mrclam import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
