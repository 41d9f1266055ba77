"""The report of benchmarks.team_runs: per-cell summaries of the runs (pooled RMSE,
wrong commits, placed frames), the PNG, the JSON and docs/results_team.md from it
(benchmarks.render.team_runs; `write`)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from benchmarks.markdown import write_report
from benchmarks.render import render as render_doc
from benchmarks.team_runs import FENG_CELLS, KAUSHIK_CELLS
from graphloc.structured import dumps_json


def _pooled(rows: list, key: str, frames: str) -> float | None:
    pairs = [(r[key], r[frames]) for r in rows if r.get(key) is not None and r.get(frames)]
    n = sum(f for _, f in pairs)
    return float(np.sqrt(sum(s for s, _ in pairs) / n)) if n else None


def summarize(rows: list) -> dict:
    out = {
        "feng-probabilistic": {},
        "kaushik-p3p-error": {},
        "breitenmoser-target": {},
        "feng-deterministic": {},
    }
    for c, k in FENG_CELLS:
        cell = [
            r
            for r in rows
            if r["scenario"] == "feng-probabilistic" and r["ceiling"] == c and r["curve"] == k
        ]
        fd = [r["front_door"] for r in cell]
        today = [r["today"] for r in cell]
        out["feng-probabilistic"][f"{c}/{k}"] = {
            "runs": len(cell),
            "runs_committed": sum(f["committed"] > 0 for f in fd),
            "wrong_decisions": sum(f["wrong"] for f in fd),
            "committed_sets": sum(f["committed"] for f in fd),
            "merged_decisions": sum(f["merged"] for f in fd),
            "batch_rmse": _pooled(fd, "batch_sq_after_commit", "frames_after_commit"),
            "online_rmse": _pooled(fd, "online_sq_after_commit", "frames_after_commit"),
            "online_causal_rmse": _pooled(fd, "causal_sq_after_commit", "frames_after_commit"),
            "today_batch_rmse": _pooled(today, "batch_sq", "frames"),
            "today_online_rmse": _pooled(today, "online_sq", "frames"),
            "today_wrong_first_locks": sum(t["wrong"] for t in today),
            **consistency(fd),
        }
    for f, v in KAUSHIK_CELLS:
        cell = [
            r
            for r in rows
            if r["scenario"] == "kaushik-p3p-error"
            and r["focal_mm"] == f
            and r["noise_variance"] == v
        ]
        fd, orc = [r["front_door"] for r in cell], [r["oracle"] for r in cell]
        out["kaushik-p3p-error"][f"{f:g} mm / {v:g} px^2"] = {
            "runs": len(cell),
            "runs_placed": sum(x["placed"] for x in fd),
            "wrong_decisions": sum(x["wrong"] for x in fd),
            "batch_rms": _pooled(fd, "batch_sq_all", "frames"),
            "online_rms": _pooled(fd, "online_sq_all", "frames"),
            "batch_offset_rms": _pooled(fd, "batch_offset_sq", "frames"),
            "batch_predicted_rms": _pooled(fd, "batch_predicted_sq", "frames"),
            "oracle_batch_rms": _pooled(orc, "batch_sq_all", "frames"),
            "oracle_batch_rms_same_runs": _pooled(
                [o for o, x in zip(orc, fd) if x["placed"]], "batch_sq_all", "frames"
            ),
            "today_batch_rms": _pooled([r["today"] for r in cell], "batch_sq", "frames"),
            **consistency(fd),
        }
    for name in ("breitenmoser-target", "feng-deterministic"):
        fd = [r["front_door"] for r in rows if r["scenario"] == name]
        out[name] = {
            "runs": len(fd),
            "runs_placed": sum(x["placed"] for x in fd),
            "committed_sets": sum(x["committed"] for x in fd),
            "candidate_sets": sum(x["candidate_sets"] for x in fd),
            "wrong_decisions": sum(x["wrong"] for x in fd),
            "batch_rmse": _pooled(fd, "batch_sq_all", "frames"),
            "online_rmse": _pooled(fd, "online_sq_all", "frames"),
            **consistency(fd),
        }
    return out


def consistency(fd: list) -> dict:
    """Runs whose batch / online solves passed their consistency test, and raised warnings."""
    return {
        f"{key}_{mode}": sum(bool(x.get(f"{key}_{mode}")) for x in fd)
        for key in ("consistent", "warnings")
        for mode in ("batch", "online")
    }


def plot(summary: dict, path: Path) -> Path:
    from graphloc.plots import Series, plot_series

    cells = list(summary["feng-probabilistic"])
    x = np.arange(len(cells), dtype=float)
    series = [
        Series(
            label,
            x,
            np.array([summary["feng-probabilistic"][c][key] or np.nan for c in cells]),
            style="o-",
        )
        for label, key in (
            ("front door batch", "batch_rmse"),
            ("front door online", "online_rmse"),
            ("today batch", "today_batch_rmse"),
            ("today online", "today_online_rmse"),
        )
    ]
    return plot_series(
        path,
        series,
        "cell (" + ", ".join(cells) + ")",
        "climber RMSE after commit [m]",
        "feng-probabilistic through the front door vs today's experiment code",
    )


def render(out: Path, doc: Path | None, command: str) -> dict:
    """The plot and markdown again from the runs saved in out/team_runs.json."""
    rows = json.loads((out / "team_runs.json").read_text())["runs"]
    return write(rows, out, doc, command)


def write(rows: list, out: Path, doc: Path | None, command: str) -> dict:
    """OUT/team_runs.json (the summary and every run), .md and the PNG; the doc (`doc`,
    benchmarks.render.team_runs) with its JSON (the command and the summary) beside it."""
    summary = summarize(rows)
    payload = json.loads(dumps_json({"summary": summary, "runs": rows}, default=str))
    rendered = {"command": command, "summary": payload["summary"]}
    text = render_doc("team_runs", rendered)
    write_report(out, "team_runs", payload, text, doc, rendered=rendered)
    plot(summary, out / "team_runs_feng.png")
    return summary
