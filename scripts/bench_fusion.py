"""Benchmark of inter-robot scan registration (issue 7 / 16; seed 004 Sec. IV-V): simulated
rooms (benchmarks.fusion_bench), `--real` the real indoor fragment
(benchmarks.fusion_bench_real), `--real --calibrate` the registration covariance's
calibration (benchmarks.fusion_calibration); the protocols are in those modules.

    .venv/bin/python scripts/bench_fusion.py --out out/bench_fusion            # 50 x 4 variants
    .venv/bin/python scripts/bench_fusion.py --real --trials 20 --out out/bench_fusion_real \
        --doc docs/results_fusion_real.md
    .venv/bin/python scripts/bench_fusion.py --real --calibrate --trials 20 --seed 1000
"""

import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one process per core; set before Open3D loads

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.fusion_bench import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
