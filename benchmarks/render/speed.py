"""docs/results_speed.md: every team run's CPU time, batch and online (scripts/bench_speed.py),
from docs/results_speed.json, and the MRCLAM Dataset6 estimator probe
(scripts/probe_mrclam_pose2.py) from docs/results_mrclam_pose2.json. Template:
templates/speed.md.j2."""

from __future__ import annotations

import pandas as pd

TARGETS = {"batch": 20.0, "online": 50.0, "mrclam_online": 300.0}  # realtime factors (CPU)


def target(name: str, mode: str) -> float:
    """The realtime factor issue 52 asks of a run in a mode."""
    return TARGETS["mrclam_online"] if (name, mode) == ("MRCLAM", "online") else TARGETS[mode]


def _runs(report: dict) -> pd.DataFrame:
    rows = []
    for name, modes in report["runs"].items():
        for mode, r in modes.items():
            goal = target(name, mode)
            steps = r.get("step_cpu_ms")
            rows.append(
                {
                    "run": name,
                    "mode": mode,
                    "duration [s]": f"{r['duration_s']:.1f}",
                    "CPU [s]": f"{r['cpu_s']:.2f}",
                    "read / build / solve [s]": (
                        f"{r['read_cpu_s']:.2f} / {r['build_cpu_s']:.2f} / {r['solve_cpu_s']:.2f}"
                    ),
                    "realtime factor": f"{r['realtime_factor']:.1f}",
                    "target": f">= {goal:g}",
                    "met": "yes" if r["realtime_factor"] >= goal else "no",
                    "step CPU p50 / p95 / max [ms]": (
                        "--"
                        if steps is None
                        else f"{steps['p50']:.2f} / {steps['p95']:.2f} / {steps['max']:.1f}"
                    ),
                    "solve / GTSAM alone": f"{r['solve_over_gtsam_alone']:.2f}",
                }
            )
    return pd.DataFrame(rows)


def _front_ends(report: dict) -> list[dict]:
    """The runs whose scans KISS-ICP alone was timed on: its CPU and realtime factor."""
    out = []
    for name, modes in report["runs"].items():
        alone = report.get("front_end_alone", {}).get(name)
        if alone is not None:
            out.append({"run": name, **alone})
    return out


def _probe(probe: dict) -> pd.DataFrame:
    rows = []
    for v in probe["variants"]:
        rows.append(
            {
                "variables": v["variables"],
                "lag [s]": f"{v['lag_s']:g}",
                "relinearize threshold": f"x{v['threshold_scale']:g}",
                "relinearize skip": str(v["relinearize_skip"]),
                "updates CPU [s]": f"{v['update_cpu_s']:.2f}",
                "updates alone realtime factor": f"{v['update_only_realtime_factor']:.0f}",
                "end to end realtime factor": f"{v['end_to_end_realtime_factor']:.0f}",
                "worst ATE / graphloc online": f"{v['worst_ate_over_graphloc']:.3f}",
            }
        )
    return pd.DataFrame(rows)


def context(report: dict, probe: dict) -> dict:
    online = report["runs"].get("MRCLAM", {}).get("online")
    variants = probe["variants"]
    reach = [
        v
        for v in variants
        if v["end_to_end_realtime_factor"] >= probe["target_realtime_factor"]
        and v["worst_ate_over_graphloc"] <= 1.01
    ]
    best = max(variants, key=lambda v: v["end_to_end_realtime_factor"])
    fixed = probe["read_cpu_s"] + probe["build_cpu_s"]
    default = {
        v["variables"]: v["update_cpu_s"]
        for v in variants
        if v["lag_s"] == probe["lag_s"]
        and v["threshold_scale"] == 1.0
        and v["relinearize_skip"] == probe["relinearize"]["skip"]
    }
    return {
        "r": report,
        "runs": _runs(report),
        "shares": [
            (name, r["update_cpu_s"], r["update_only_realtime_factor"])
            for name, modes in report["runs"].items()
            if "update_cpu_s" in (r := modes.get("online", {}))
        ],
        "front_ends": _front_ends(report),
        "b": report["bearing_linearization"],
        "probe": probe,
        "probe_table": _probe(probe),
        "probe_reach": reach,
        "probe_best": best,
        "probe_fixed_s": fixed,
        "budget_s": probe["duration_s"] / probe["target_realtime_factor"],
        "pose2_over_pose3": default["Pose2"] / default["Pose3"],
        "mrclam_online": online,
        "target_mrclam": TARGETS["mrclam_online"],
        "targets": TARGETS,
    }
