"""Online and batch at scale (issue 15) on MRCLAM Dataset6: graphloc batch vs GTSAM-only LM
on the same graph, online with full iSAM2 and fixed lags (latency first vs last tenth, slowest
step, real-time factor, ATE vs batch, memory), and the run replayed COPIES times with a
shifted clock through the default lag. Writes bench_scale.json (every number computed here)
and, with --markdown, docs/results_scale.md from it and a copy of the JSON beside it.

Thin wrapper: the code is benchmarks.bench_scale (its options: `--help`)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.bench_scale import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
