"""docs/results_team_dual_room.md: dual-robot-room through the front door, the ground ->
ceiling transform of the team graph and of map fusion (benchmarks.team_dual_room), from the
doc's JSON (command, seeds, summary). Template: templates/team_dual_room.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render import header
from benchmarks.render.numbers import fmt
from benchmarks.team_dual_room import METHODS, TARGET
from graphloc.datasets.dual_room import VARIANTS


def context(report: dict) -> dict:
    rows = []
    for v in VARIANTS:
        cell = report["summary"][v]
        for m in METHODS:
            c = cell[m]
            rows.append(
                [v, m, f"{c['placed']} / {cell['runs']}", f"{c['within_target']} / {cell['runs']}"]
                + [fmt(c[k], ".3f", "-") for k in ("median_rot_deg", "max_rot_deg")]
                + [fmt(c[k], ".3f", "-") for k in ("median_trans_cm", "max_trans_cm")]
            )
    columns = header("variant | method | placed | within target | median rot [deg] | "
                     "max rot [deg] | median trans [cm] | max trans [cm]")  # fmt: skip
    return {"report": report, "target": TARGET, "errors": pd.DataFrame(rows, columns=columns)}
