"""docs/gtsam_isam2_chain.md: GTSAM 4.3's whole-tree walk in `ISAM2::update` on a plain Pose2
chain (scripts/bench_isam2_chain.py) from the doc's JSON: every run's per-update CPU, first vs
last tenth, and the findings. Template: templates/isam2_chain.md.j2."""

from __future__ import annotations

import pandas as pd


def _row(run: dict) -> dict:
    change = ", ".join(f"`{k} = {v}`" for k, v in run["params"].items()) or "none (defaults)"
    first, last = run["first10"], run["last10"]
    return {
        "GTSAM": run["gtsam"], "ISAM2Params change": change,
        "prior": "every pose" if run["prior_every_pose"] else "first",
        "mean first / last 10 % [ms]": f"{first['mean_ms']:.3f} / {last['mean_ms']:.3f}",
        "last / first": f"{run['last_over_first_mean']:.1f}",
        "median last 10 % [ms]": f"{last['median_ms']:.3f}",
        "slope [ms per 1,000 poses]": f"{run['slope_ms_per_1000_poses']:.3f}",
        "total [s]": f"{run['total_s']:.1f}",
    }  # fmt: skip


def context(report: dict) -> dict:
    runs = report["runs"]
    first = runs[0]["gtsam"]  # the install that ran every ISAM2Params variant
    defaults = [x for x in runs if x["variant"] == "defaults" and x["prior_every_pose"]]
    variants = [x for x in runs if x["gtsam"] == first and x["prior_every_pose"]]
    best = min(variants, key=lambda x: x["last10"]["median_ms"])
    base = next(x for x in defaults if x["gtsam"] == first)
    return {
        "r": report,
        "runs": pd.DataFrame([_row(x) for x in runs]),
        "first": first,
        "defaults": defaults,
        "best": best,
        "base": base,
        # no parameter removes the growth unless the best one halves the defaults' median
        "growth_stays": best["last10"]["median_ms"] > 0.5 * base["last10"]["median_ms"],
    }
