"""docs/results_scale.md: online and batch at scale on MRCLAM Dataset6 (issue 15,
benchmarks.bench_scale) from the doc's JSON: batch against GTSAM alone, online per lag, ATE
per robot, the default lag's look-ahead, relinearization and marginalization batch sizes, the
long replayed run. Template: templates/scale.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render.numbers import fmt


def _batch(b: dict) -> pd.DataFrame:
    rows = [["graphloc `solve(graph, 'batch')` (warm start + LM)", f"{b['graphloc_wall_s']:.2f}",
             f"{b['graphloc_cpu_s']:.2f}", "", f"{b['graphloc_error']:.1f}"]]  # fmt: skip
    for name, g in (
        ("GTSAM `LevenbergMarquardtOptimizer.optimize()` from the guess", b["gtsam_only"]),
        ("GTSAM LM from graphloc's warm start (LM only)", b["gtsam_only_from_warm_start"]),
    ):
        rows.append([name, f"{g['wall_s']:.2f}", f"{g['cpu_s']:.2f}", g["iterations"],
                     f"{g['error']:.1f}"])  # fmt: skip
    rows.append(["ratio graphloc / GTSAM from the guess (target <= 1.5)",
                 f"{b['ratio_wall']:.2f}", f"{b['ratio_cpu']:.2f}", "", ""])  # fmt: skip
    return pd.DataFrame(rows, columns=["", "wall [s]", "CPU [s]", "LM iterations", "error"])


def _online(r: dict) -> pd.DataFrame:
    rows = []
    for lag, o in r["online"].items():
        t = o["trend"]
        worst = max(o["ate_over_batch"].values()) if o.get("ate_over_batch") else float("nan")
        rows.append({
            "lag [s]": "full" if lag == "0" else lag,
            "p95 CPU first / last 10 % [ms]":
                f"{t['cpu_p95_first10_ms']:.2f} / {t['cpu_p95_last10_ms']:.2f}",
            "ratio": f"{t['cpu_p95_last_over_first']:.2f}",
            "slowest step CPU [ms]": f"{t['cpu_max_ms']:.1f}",
            "p95 wall [ms]": f"{o['latency_ms']['p95']:.2f}",
            "variables at end": t["variables_end"],
            "real time x (wall / CPU)":
                f"{o['realtime_factor']:.0f} / {o['realtime_factor_cpu']:.0f}",
            "max ATE / batch": f"{worst:.3f}",
            "dropped": sum(o["dropped_across_lag"].values()),
        })  # fmt: skip
    return pd.DataFrame(rows)


def _ate(r: dict) -> pd.DataFrame:
    rows = [
        {"robot": name, "batch": f"{a:.4f}"}
        | {
            f"online lag {k}": f"{o['ate_rmse_m'].get(name, float('nan')):.4f}"
            for k, o in r["online"].items()
        }
        for name, a in r["batch"]["ate_rmse_m"].items()
    ]
    return pd.DataFrame(rows)


def _lookahead(r: dict) -> pd.DataFrame:
    look, lags = r["lookahead"], [k for k in r["online"] if k != "0"]
    default = f"{r['default_lag_s']:g}"
    rows = []
    for name, gap, tenths in zip(
        look["robots"], look["gaps"], look["tenth_error_ratio_default_lag"], strict=True
    ):
        row = {"robot": name, "longest stretch [s] (starts at [s])":
               f"{gap['longest_gap_s']:.0f} ({gap['gap_start_s']:.0f})"}  # fmt: skip
        for k in lags:
            row[f"ATE / batch lag {k}"] = fmt(
                r["online"][k].get("ate_over_batch", {}).get(name), ".3f", "-"
            )
        row[f"online / batch error per tenth at lag {default}"] = (
            "-" if tenths is None else " ".join(f"{x:.2f}" for x in tenths)
        )
        rows.append(row)
    return pd.DataFrame(rows)


def _relinearize(r: dict) -> pd.DataFrame:
    robots = r["batch"]["ate_rmse_m"]
    runs = {f"{r['relinearize_translation_default']:g}": r["online"][f"{r['default_lag_s']:g}"]}
    runs.update(r["online_relinearize"])
    rows = []
    for thr, o in runs.items():
        t = o["trend"]
        rows.append({
            "translation threshold [m]": thr, "CPU [s]": f"{o['cpu_s']:.1f}",
            "real time x (CPU)": f"{o['realtime_factor_cpu']:.0f}",
            "p95 CPU last 10 % [ms]": f"{t['cpu_p95_last10_ms']:.2f}",
            "slowest step CPU [ms]": f"{t['cpu_max_ms']:.1f}",
        } | {f"{n} ATE / batch": f"{o['ate_over_batch'].get(n, float('nan')):.3f}"
             for n in robots})  # fmt: skip
    return pd.DataFrame(rows)


def _marginalize_every(r: dict) -> pd.DataFrame:
    """The default lag at each marginalization batch size, with the p95 ratio over the steps
    that did not marginalize (`benchmarks.scale.marginalization_split`)."""
    runs = {f"{r['marginalize_every_s']:g}": r["online"][f"{r['default_lag_s']:g}"]}
    runs.update(r["online_marginalize_every"])
    rows = []
    for every, o in sorted(runs.items(), key=lambda kv: float(kv[0])):
        t, m = o["trend"], o["marginalization"]
        rows.append([
            every, f"{o['cpu_s']:.1f}", f"{o['realtime_factor_cpu']:.0f}",
            f"{t['cpu_p95_first10_ms']:.2f} / {t['cpu_p95_last10_ms']:.2f}",
            f"{t['cpu_p95_last_over_first']:.2f}",
            f"{100 * m['share_first10']:.1f} % / {100 * m['share_last10']:.1f} %",
            f"{m['cpu_p95_first10_other_ms']:.2f} / {m['cpu_p95_last10_other_ms']:.2f}",
            f"{m['cpu_p95_other_last_over_first']:.2f}", f"{t['cpu_max_ms']:.1f}",
            f"{max(o['ate_over_batch'].values()):.3f}",
        ])  # fmt: skip
    columns = ["marginalize every [s]", "CPU [s]", "real time x (CPU)",
               "p95 CPU first / last 10 % [ms]", "ratio",
               "marginalizing steps first / last 10 %",
               "p95 CPU of the other steps first / last 10 % [ms]", "ratio",
               "slowest step CPU [ms]", "max ATE / batch"]  # fmt: skip
    return pd.DataFrame(rows, columns=columns)


def context(r: dict) -> dict:
    return {
        "r": r,
        "batch": _batch(r["batch"]),
        "online": _online(r),
        "ate": _ate(r),
        "lookahead": _lookahead(r) if r.get("lookahead") else None,
        "relinearize": _relinearize(r) if r.get("online_relinearize") else None,
        "marginalize_every": (_marginalize_every(r) if r.get("online_marginalize_every") else None),
        "num": lambda x, spec=".2f": fmt(x, spec, "-"),
    }
