"""docs/results_candidate_engines.md: the HypothesisTracker and PoseGraphHypotheses on the same
candidate-set streams (scripts/bench_candidate_engines.py, benchmarks.candidate_engines, issue
51) from the doc's JSON. Template: templates/candidate_engines.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render.numbers import significant, yes_no

COLUMNS = {
    "input": "input",
    "cell": "cell",
    "method": "method",
    "runs": "runs",
    "mean_updates_to_correct_lock": "updates to correct lock (locked runs)",
    "mean_updates_to_correct_lock_censored": "updates to correct lock (never: length)",
    "never_correct": "never correct",
    "wrong_locks": "wrong first locks",
    "wrong_locked_frame_fraction": "wrong locked-frame fraction",
    "locked_frame_share": "locked frames / frames",
    "rmse_locked_frames_m": "RMSE locked [m]",
    "mean_latency_ms": "latency [ms]",
    "cpu_s": "CPU [s]",
}
VERDICT_COLUMNS = {
    "input": "input",
    "cell": "cell",
    "method": "method",
    "updates_to_correct_lock_vs_tracker": "updates to correct lock - tracker's",
    "wrong_locks_vs_tracker": "wrong locks - tracker's",
    "as_good": "as good as the tracker",
    "cpu_ratio": "CPU / tracker's",
}


def context(report: dict) -> dict:
    rows = pd.DataFrame(report["rows"])[list(COLUMNS)].rename(columns=COLUMNS)
    verdict = pd.DataFrame(report["verdict"])
    counts = [
        {
            "method": method,
            "cells as good as the tracker": f"{int(part.as_good.sum())} / {len(part)}",
            "median CPU / tracker's": float(part.cpu_ratio.median()),
        }
        for method, part in verdict.groupby("method", sort=False)
    ]
    verdict["as_good"] = verdict["as_good"].map(yes_no)
    verdict = verdict[list(VERDICT_COLUMNS)].rename(columns=VERDICT_COLUMNS)
    settings = [
        {"method": m, "settings": ", ".join(f"{k}={v}" for k, v in s.items()) or "defaults"}
        for m, s in report["methods"].items()
    ]
    growth = pd.DataFrame(report.get("growth", []))
    return {
        "report": report,
        "growth": significant(growth.astype(object).where(growth.notna(), "n/a"), 3),
        "rows": significant(rows.astype(object).where(rows.notna(), "n/a"), 3),
        "verdict": significant(verdict, 3),
        "counts": significant(pd.DataFrame(counts), 3),
        "settings": pd.DataFrame(settings),
    }
