"""dual-robot-room through the front door (`graphloc simulate dual-robot-room` -> `smooth` /
`online`) beside the map-fusion pipeline on the same runs, every variant: JSON, markdown and PNG
(benchmarks.team_dual_room).

    .venv/bin/python scripts/bench_team_dual_room.py --out out/team_dual_room \
        --doc docs/results_team_dual_room.md
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.team_dual_room import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
