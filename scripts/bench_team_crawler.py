"""crawler-pair through the front door (`graphloc simulate crawler-pair` -> `smooth` / `online`)
beside the seed's EKF on the same front-end measurements, N = 1, 2, 10, 20: JSON, markdown and
PNG (graphloc.experiments.team_crawler).

    .venv/bin/python scripts/bench_team_crawler.py --out out/team_crawler \
        --doc docs/results_team_crawler.md
"""

import sys

from graphloc.experiments.team_crawler import main

if __name__ == "__main__":
    sys.exit(main())
