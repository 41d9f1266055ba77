"""docs/results_g2o_outliers.md (and _sphere2500.md): outlier loop closures injected into
public g2o pose graphs, graphloc online beside GNC (scripts/bench_g2o_outliers.py,
benchmarks.g2o_outliers, issue 51), from the doc's JSON. Template:
templates/g2o_outliers.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render.numbers import significant

# [m] RMSEs this close are one: both methods at the outlier-free optimum, differing by their
# optimizers' stopping tolerances (Intel: 0.006846252 against 0.006846... m)
SAME_M = 1e-6


def context(report: dict) -> dict:
    frame = pd.DataFrame(report["rows"])
    verdict = []
    for (graph, rate), part in frame.groupby(["graph", "rate"]):
        g = part[part.method == "graphloc"].iloc[0]
        n = part[part.method == "gnc"].iloc[0]
        verdict.append(
            {
                "graph": graph,
                "rate": rate,
                "graphloc RMSE": g.rmse_m,
                "GNC RMSE": n.rmse_m,
                "graphloc <= GNC": "yes" if g.rmse_m <= n.rmse_m + SAME_M else "**no**",
            }
        )
    return {
        "report": report,
        "runs": significant(_rounded(frame), 4),
        "verdict": significant(pd.DataFrame(verdict), 4),
        "same_um": SAME_M * 1e6,
        "objective": "objective_above_reference" in frame,
    }


def _rounded(frame: pd.DataFrame) -> pd.DataFrame:
    """Four decimals, but for the objective's excess over the reference (small where both
    optima are close: significant digits only)."""
    out = frame.round(4)
    if "objective_above_reference" in frame:
        out["objective_above_reference"] = frame["objective_above_reference"]
    return out
