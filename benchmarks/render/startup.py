"""docs/results_startup.md: start-up, Ctrl-C and demo times (scripts/bench_startup.py) from
docs/results_startup.json. Template: templates/startup.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render import header
from benchmarks.render.numbers import fmt


def s(v, digits: int = 3) -> str:
    """v to `digits` decimals, "-" for a time that was not measured."""
    return fmt(v, f".{digits}f", "-")


def _startup(result: dict) -> dict:
    names = [n for n in ("graphloc", "peer") if n in result["startup"][0]]
    header = ["command"]
    for n in names:
        header += [f"{n} wall median [s]", f"{n} wall max [s]", f"{n} peak RSS [MB]"]
    if "peer" in names:
        header.append("wall ratio graphloc / peer")
    rows = []
    for r in result["startup"]:
        row = [f"`{r['command']}`"]
        for n in names:
            row += [
                s(r[n]["wall_s"]["median"]),
                s(r[n]["wall_s"]["max"]),
                s(r[n]["peak_rss_mb"]["median"], 0),
            ]
        if "peer" in names:
            row.append(s(r["graphloc"]["wall_s"]["median"] / r["peer"]["wall_s"]["median"], 2))
        rows.append(row)
    return {
        "peer": "peer" in names,
        "all_zero": all(r[n]["exit_codes"] == [0] for r in result["startup"] for n in names),
        "table": pd.DataFrame(rows, columns=header),
    }


def _sigint(result: dict) -> pd.DataFrame:
    rows = [
        [
            x["command"],
            f"`{x['verb']}`",
            x["run"],
            s(x["uninterrupted_s"], 1),
            f"{sum(t['signalled'] for t in x['trials'])} / {len(x['trials'])}",
            s(x["exit_s"]["median"] if x["exit_s"] else None, 2),
            s(x["exit_s"]["max"] if x["exit_s"] else None, 2),
            ",".join(sorted({str(t["exit_code"]) for t in x["trials"] if t["signalled"]})),
            sum(t["traceback"] for t in x["trials"]),
            sum(t["metrics_partial"] is True for t in x["trials"]),
        ]
        for x in result["sigint"]
    ]
    columns = header(
        "command | verb | run | uninterrupted [s] | trials signalled | exit median [s] | "
        "exit max [s] | exit codes | tracebacks | partial metrics"
    )
    return pd.DataFrame(rows, columns=columns)


def context(result: dict) -> dict:
    return {
        "r": result,
        "startup": _startup(result) if result.get("startup") else None,
        "sigint": _sigint(result) if result.get("sigint") else None,
        "s": s,
    }
