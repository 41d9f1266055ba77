"""docs/results_executor.md: graphloc.executor's local pool and Ray on many runs (issue 19,
scripts/bench_executor.py) from docs/results_executor.json: wall time and runs per minute per
configuration and the cached re-run; the overhead, speed-up and spread the template states.
Template: templates/executor.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render import header


def _configs(r: dict) -> pd.DataFrame:
    rows = [
        [
            m["backend"],
            m["workers"],
            f"{m['wall_s']:.1f} ({', '.join(f'{w:.1f}' for w in m['wall_s_each'])})",
            f"{m['runs_per_min']:.1f}",
            f"{m['task_s_median']:.2f}",
            str(m["statuses"]),
        ]
        for m in r["configs"]
    ]
    c = r["cached_rerun"]
    rows.append(
        [
            f"{c['backend']} (re-run, cache)",
            c["workers"],
            f"{c['wall_s']:.1f}",
            f"{c['runs_per_min']:.1f}",
            "-",
            str(c["statuses"]),
        ]
    )
    columns = header(
        "backend | workers | wall [s] (each repeat) | runs / min | median task [s] | runs"
    )
    return pd.DataFrame(rows, columns=columns)


def context(r: dict) -> dict:
    return {
        "r": r,
        "configs": _configs(r),
        # max - min of a configuration's repeats over their mean, the worst configuration
        "spread": max(
            (max(m["wall_s_each"]) - min(m["wall_s_each"])) / m["wall_s"] for m in r["configs"]
        ),
        "order": ", ".join(f"{b} {w}" for _, b, w in r["order"]),
    }
