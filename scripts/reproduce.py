"""Recompute one seed table and print it as markdown (benchmarks.reproduce, the route
scripts/make_results.py takes for docs/results.md): seed000-table1/2/3, seed004-table1,
seed001-exp1. JSON to OUT/<table>.json; a re-run prints the table cached under OUT/.cache;
--results DOC replaces the table's entry of DOC's JSON (docs/results.json) and re-renders DOC.

    .venv/bin/python scripts/reproduce.py seed000-table1 --quick [--out out/reproduce]
    .venv/bin/python scripts/reproduce.py seed004-table1 --backend ray --workers 8 --no-cache
    .venv/bin/python scripts/reproduce.py seed000-table2 --no-cache --results docs/results.md
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.reproduce import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
