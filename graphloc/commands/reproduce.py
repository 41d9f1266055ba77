"""`graphloc reproduce TABLE [--quick] [--out DIR]`: recompute one seed table (graphloc.tables)
and print it as markdown; JSON goes to DIR/<table>.json. Full-size runs with plots:
scripts/repro_seed000.py, scripts/repro_seed004.py, scripts/make_results.py."""

from __future__ import annotations

import json
from pathlib import Path

HELP = "reproduce a seed table: seed000-table1/2/3, seed004-table1, seed001-exp1"
TABLES = ("seed000-table1", "seed000-table2", "seed000-table3", "seed004-table1", "seed001-exp1")


def add_arguments(parser) -> None:
    parser.add_argument("table", choices=TABLES)
    parser.add_argument("--quick", action="store_true", help="CI size (100 trials / 5 runs per cell / 50 tracks)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("out/reproduce"))


def reproduce(table: str, quick: bool, workers: int, out: Path) -> tuple[dict | None, str]:
    from graphloc import tables

    if table == "seed001-exp1":  # writes its own JSON / PNG under out/seed001
        return None, tables.seed001_experiment(out / "seed001", quick)
    if table == "seed000-table1":
        r = tables.table_i(tables.TableIConfig(trials=100 if quick else 1000, workers=workers))
        return r, tables.markdown_table_i(r)
    if table in ("seed000-table2", "seed000-table3"):
        t3 = tables.table_iii(tables.TableIIIConfig(runs=5 if quick else 100, workers=workers))
        if table == "seed000-table3":
            return t3, tables.markdown_table_iii(t3)
        r = tables.table_ii(t3, samples=100)
        return r, tables.markdown_table_ii(r)
    r = tables.seed004_table_1(runs=50 if quick else 1000, workers=workers)
    return r, tables.markdown_seed004(r)


def run(args) -> int:
    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    args.out.mkdir(parents=True, exist_ok=True)
    result, md = reproduce(args.table, args.quick, args.workers, args.out)
    if result is not None:
        (args.out / f"{args.table}.json").write_text(json.dumps(result, indent=2, default=float))
    print(md)
    return 0
