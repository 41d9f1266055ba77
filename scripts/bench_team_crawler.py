"""crawler-pair through the front door (`graphloc simulate crawler-pair` -> `smooth` / `online`)
beside the seed's EKF on the same front-end measurements, N = 1, 2, 10, 20: JSON, markdown and
PNG (benchmarks.team_crawler).

    .venv/bin/python scripts/bench_team_crawler.py --out out/team_crawler \
        --doc docs/results_team_crawler.md
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.team_crawler import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
