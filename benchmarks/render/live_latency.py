"""docs/results_live_latency.md: the live latency benchmark (scripts/bench_live_latency.py) from
docs/results_live_latency.json, and the live API against `graphloc online` on the full
Dataset6 (scripts/bench_live.py) from docs/results_live.json. Template:
templates/live_latency.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render import header


# the parts of the update's span (`breakdown_s`), as the table names them
BREAKDOWN = (
    ("queued (arrived -> taken by the run loop)", "queue"),
    ("before the step (taken -> step began)", "before"),
    ("step (iSAM2 update + covariances), wall", "step"),
    ("step, CPU", "step_cpu"),
    ("sinks (ready -> published)", "sinks"),
    ("poses of a push's later steps (arrived -> ready)", "later"),
)


def ms(x) -> str:
    return "-" if x is None else f"{1e3 * x:.2f}"


def _steps(result: dict) -> pd.DataFrame:
    rows = [
        [
            s["team"],
            s["steps"],
            ms(s["latency_s"].get("p50")),
            ms(s["latency_s"].get("p95")),
            ms(s["latency_s"].get("max")),
            f"{s['wall_s']:.1f}",
            s["skipped"],
        ]
        for s in result["steps"]
    ]
    cols = "robots | updates | p50 [ms] | p95 [ms] | max [ms] | replay wall [s] | skipped rows"
    return pd.DataFrame(rows, columns=header(cols))


def _e2e(result: dict) -> pd.DataFrame:
    rows = []
    for e in result["end_to_end"]:
        parts = e.get("breakdown_s", {})  # the update's span split (benchmarks/live_latency.py)
        for part, st in (
            ("end to end", e["end_to_end_s"]),
            ("way in (published -> arrived)", e["way_in_s"]),
            ("update (arrived -> poses ready)", e["update_s"]),
            *(
                (f"- update: {name}", parts[key])
                for name, key in BREAKDOWN
                if key in parts and parts[key]["n"]
            ),
            ("way out (ready -> received)", e["way_out_s"]),
            ("age (newest row at the pose's time published -> received)", e["age_s"]),
        ):
            rows.append(
                [
                    f"{e['window_s']:g}",
                    part,
                    st["n"],
                    ms(st.get("p50")),
                    ms(st.get("p95")),
                    ms(st.get("max")),
                ]
            )
    cols = "window [s] | part | poses | p50 [ms] | p95 [ms] | max [ms]"
    return pd.DataFrame(rows, columns=header(cols))


def _api(api: dict) -> pd.DataFrame:
    rows = [
        [
            name,
            f"{run['cpu_s']:.1f}",
            f"{run['cpu_s'] / api['online']['cpu_s']:.2f}",
            *(f"{run['latency'][q]:.2f}" for q in ("p50_ms", "p95_ms", "max_ms")),
            *(f"{run['step_cpu'][q]:.2f}" for q in ("p50_ms", "p95_ms", "max_ms")),
        ]
        for name, run in (("live", api["live"]), ("live, covariances", api["live_with_covariance"]))
    ]
    cols = (
        "replay | CPU [s] | CPU / online's | latency p50 [ms] | p95 [ms] | max [ms] "
        "| step CPU p50 [ms] | p95 [ms] | max [ms]"
    )
    return pd.DataFrame(rows, columns=header(cols))


def context(result: dict, api: dict | None = None) -> dict:
    target = result["target_p95_s"]
    verdicts = [
        {
            "window": e["window_s"],
            "p95_ms": 1e3 * e["end_to_end_s"]["p95"],
            "met": e["end_to_end_s"]["p95"] < target,
            "messages": e["messages"],
            "poses": e["poses"],
            "missing": e["poses_not_received"],
            "skipped": e["skipped"],
            "skip_counts": e["skip_counts"],
        }
        for e in result["end_to_end"]
        if e["end_to_end_s"]["n"]
    ]
    return {
        "r": result,
        "steps": _steps(result),
        "e2e": _e2e(result),
        "verdicts": verdicts,
        "target_ms": 1e3 * target,
        "api": api,
        "api_table": None if api is None else _api(api),
    }
