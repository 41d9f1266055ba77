"""docs/results_team_crawler.md: crawler-pair through the front door, graphloc against the
seed 003 EKF (benchmarks.team_crawler), from the doc's JSON (command, trials, summary).
Template: templates/team_crawler.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render import header
from benchmarks.team_crawler import METHODS, N_VALUES


def context(report: dict) -> dict:
    rows = []
    for n in N_VALUES:
        cell = report["summary"][str(n)]
        for m in METHODS:
            c = cell[m]
            rows.append(
                [n, m]
                + [f"{a:.3f} ± {s:.3f}" for a, s in zip(c["mean_mm"], c["std_mm"])]
                + (
                    ["", ""]
                    if m == "ekf"
                    else [
                        "yes" if c["below_ekf_every_axis"] else "NO",
                        f"{c['wrong']} / {c['sightings']}",
                    ]
                )
            )
    columns = header("N | method | x [mm] | y [mm] | z [mm] | below EKF on every axis | "
                     "wrong / sightings")  # fmt: skip
    return {"report": report, "errors": pd.DataFrame(rows, columns=columns)}
