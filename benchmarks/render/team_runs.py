"""docs/results_team.md: every scenario through `graphloc smooth` / `online`
(benchmarks.team_runs) from the doc's JSON (command, per-cell summary of
benchmarks.team_runs_report.summarize). Template: templates/team_runs.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render import header
from benchmarks.render.numbers import fmt


def _f(x) -> str:
    return fmt(x, ".4f", "--")


def _consistent(s: dict) -> str:
    """Consistent batch / online runs (runs with a warning)."""
    if "consistent_batch" not in s:
        return "--"
    return (
        f"{s['consistent_batch']} / {s['consistent_online']} "
        f"({s['warnings_batch']} / {s['warnings_online']})"
    )


def _feng(cells: dict) -> pd.DataFrame:
    rows = [
        [cell, f"{s['runs']} ({s['runs_committed']})",
         f"{s['wrong_decisions']} / {s['merged_decisions']} / {s['committed_sets']}",
         _f(s["batch_rmse"]), _f(s["online_rmse"]), _f(s["online_causal_rmse"]),
         _f(s["today_batch_rmse"]), _f(s["today_online_rmse"]), s["today_wrong_first_locks"],
         _consistent(s)]
        for cell, s in cells.items()
    ]  # fmt: skip
    columns = header("cell | runs (committed) | wrong / merged / decided sets | front door batch"
                     " | online | online causal | today's experiment code batch | online | its "
                     "wrong first locks | consistent batch / online (warned)")  # fmt: skip
    return pd.DataFrame(rows, columns=columns)


def _kaushik(cells: dict) -> pd.DataFrame:
    rows = [
        [cell, f"{s['runs']} ({s['runs_placed']})", s["wrong_decisions"], _f(s["batch_rms"]),
         _f(s["batch_offset_rms"]), _f(s["batch_predicted_rms"]), _f(s["online_rms"]),
         _f(s["oracle_batch_rms"]), _f(s["oracle_batch_rms_same_runs"]),
         _f(s["today_batch_rms"]), _consistent(s)]
        for cell, s in cells.items()
    ]  # fmt: skip
    columns = header("cell | runs (placed) | wrong decisions | front door batch | its one-offset "
                     "part | predicted by its covariance | online | oracle batch, uses the truth "
                     "(all runs) | oracle (the placed runs) | today's experiment code, uses the "
                     "truth | consistent batch / online (warned)")  # fmt: skip
    return pd.DataFrame(rows, columns=columns)


def _others(summary: dict) -> pd.DataFrame:
    rows = [
        [name, f"{s['runs']} ({s['runs_placed']})",
         f"{s['committed_sets']} / {s['candidate_sets']}", s["wrong_decisions"],
         _f(s["batch_rmse"]), _f(s["online_rmse"]), _consistent(s)]
        for name in ("breitenmoser-target", "feng-deterministic")
        for s in [summary[name]]
    ]  # fmt: skip
    columns = header("scenario | runs (placed) | committed / candidate sets | wrong | batch RMSE "
                     "[m] | online RMSE [m] | consistent batch / online (warned)")  # fmt: skip
    return pd.DataFrame(rows, columns=columns)


def context(report: dict) -> dict:
    summary = report["summary"]
    kaushik = summary["kaushik-p3p-error"].values()
    return {
        "command": report["command"],
        "feng": _feng(summary["feng-probabilistic"]),
        "kaushik": _kaushik(summary["kaushik-p3p-error"]),
        "others": _others(summary),
        "below_today": all(s["batch_rms"] <= s["today_batch_rms"] for s in kaushik),
        "below_oracle": sum(s["batch_rms"] <= s["oracle_batch_rms"] for s in kaushik),
        "kaushik_cells": len(kaushik),
    }
