"""docs/results_seed_baselines.md (issue 20) from docs/results_seed_baselines.json, the
result of scripts/bench_seed_baselines.py (benchmarks.seed_baselines_report): per seed table
the readings swept (benchmarks.seed_baselines), the chosen one and graphloc at the stated and
the chosen setting; seed 000's bounds (benchmarks.render.seed_baselines_bounds) and seed 001 /
003 (benchmarks.render.seed_baselines_more). Template: templates/seed_baselines.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render import header

from benchmarks.render.seed_baselines_bounds import table1_bounds, table3_bounds
from benchmarks.render.numbers import dev, fmt
from benchmarks.render.seed_baselines_more import seed001, seed003
from benchmarks.seed_baselines import PAPER_LINE_ERRORS

T1_STATED = (0.5, 0.001, "kept")
T3_STATED = (0.5, "per_axis", "inner_product", "solution")
S4_STATED = (2.5, 13.75, 0.0, "variance")
SETTINGS = ("stated", "reproducing")


def top(rows: list, stated, n: int = 8) -> list:
    """The stated reading's row first, then the n best others by largest deviation."""
    first = [r for r in rows if stated(r)]
    rest = sorted((r for r in rows if not stated(r)), key=lambda r: r["max_deviation"])
    return first + rest[:n]


def _pair(x) -> str:
    return "n/a" if x is None else f"{x[0]:.1e} ({x[1]:.1e})"


def _table1(sw: dict) -> dict:
    p, best = sw["paper"], sw["choice"]["best"]
    rows = [
        [
            "paper",
            "",
            "",
            p["success"],
            _pair(p["C2"]),
            _pair(p["C3"]),
            _pair(p["C"]),
            f"{fmt(PAPER_LINE_ERRORS['genuine_mean'])} / {fmt(PAPER_LINE_ERRORS['genuine_max'])}",
            f"{PAPER_LINE_ERRORS['second_mean']:.3f}",
            "",
        ]
    ]
    shown = top(
        sw["rows"], lambda x: (x["pixel_sigma"], x["lateral_sigma"], x["orientation"]) == T1_STATED
    )
    for x in shown:
        rows.append(
            [
                f"{x['pixel_sigma']:g}",
                f"{x['lateral_sigma']:g}",
                x["orientation"],
                f"{1000 * x['correct'] / x['trials']:.0f}",
                _pair(x["C2"]),
                _pair(x["C3"]),
                _pair(x["C"]),
                f"{fmt(x['line_genuine_mean_m'])} / {fmt(x['line_genuine_max_m'])}",
                f"{fmt(x['line_second_mean_m'], '.3f')} / "
                f"{fmt(x['line_second_pseudo_middle_mean_m'], '.3f')}",
                dev(x["max_deviation"]),
            ]
        )
    columns = header(
        "image std [px] | lateral [m] | orientation | correct /1000 | C2 | C3 | C | "
        "genuine line mean / max [m] | runner-up mean (any / 2nd pseudo) [m] | largest dev."
    )
    # where each number alone is met best, at the chosen reading's lateral noise / orientation
    same = [
        x
        for x in sw["rows"]
        if x["lateral_sigma"] == best["lateral_sigma"] and x["orientation"] == best["orientation"]
    ]

    def argbest(key):
        x = min(same, key=lambda x: x["deviation"][key])
        return f"{x['pixel_sigma']:g} px (dev. {dev(x['deviation'][key])})"

    return {
        "sweep": pd.DataFrame(rows, columns=columns),
        "shown": len(shown) - 1,
        "best_alone": {
            k: argbest(k)
            for k in ("correct", "C2_mean", "C_mean", "line_genuine_mean", "line_second_mean")
        },
    }


def table1_by_setting(runs: dict) -> pd.DataFrame:
    """Seed 000 Table I, seed baseline | graphloc at the stated and the reproducing setting."""
    paper = runs["stated"]["table1"]["paper"]
    rows = [
        [
            "paper",
            f"{paper['success']}/{paper['trials']}",
            "",
            fmt(paper["C2"][0]),
            fmt(paper["C"][0]),
        ]
    ]
    for name in SETTINGS:
        t = runs[name]["table1"]
        s, g = t["seed_baseline"], t["graphloc"]
        rows.append(
            [
                f"{name} ({t['config']['pixel_sigma']:g} px)",
                f"{s['success']}/{t['trials']}",
                f"{g['success']}/{t['trials']}",
                f"{fmt(s['C2']['mean'])} / {fmt(g['C2']['mean'])}",
                f"{fmt(s['C']['mean'])} / {fmt(g['C']['mean'])}",
            ]
        )
    columns = header(
        "setting | seed correct (genuine picked) | graphloc correct | C2 seed / graphloc | "
        "C seed / graphloc"
    )
    return pd.DataFrame(rows, columns=columns)


def _table3(sw: dict) -> dict:
    best = sw["choice"]["best"]
    names = list(best["cells"])
    rows = [
        ["paper", "", "", ""] + [f"{best['cells'][n]['paper']:g}" for n in names] + ["", "", "0"]
    ]
    for x in top(
        sw["rows"],
        lambda x: (
            (x["pixel_sigma"], x["odometry_model"], x["likelihood"], x.get("action_frame"))
            == T3_STATED
        ),
    ):
        rows.append(
            [
                f"{x['pixel_sigma']:g}",
                x["odometry_model"],
                x["likelihood"],
                x.get("action_frame", "solution"),
            ]
            + [
                f"{fmt(x['cells'][n]['mean_updates_to_converge'], '.2f')} "
                f"({x['cells'][n]['wrong_locks']})"
                for n in names
            ]
            + [dev(x["max_deviation"]), x["wrong_locks"], x["runs_with_relocalization"]]
        )
    columns = (
        ["image std [px]", "odometry", "likelihood", "action frame"]
        + names
        + ["largest dev.", "wrong", "relocalized"]
    )
    rows_all = sw["rows"]
    clean = [x for x in rows_all if x["wrong_locks"] == 0]
    return {
        "sweep": pd.DataFrame(rows, columns=columns),
        "runs_per_cell": best["cells"][names[0]]["runs"],
        # evidence: readings free of wrong locks, cells within 10 %, relocalized runs
        "clean": len(clean),
        "best_clean": min(clean, key=lambda x: x["max_deviation"]) if clean else None,
        "runs": sum(c["runs"] for c in rows_all[0]["cells"].values()),
        "within": max(sum(c["deviation"] <= 0.1 for c in x["cells"].values()) for x in rows_all),
        "relocalized": min(x["runs_with_relocalization"] for x in rows_all),
    }


def table3_by_setting(runs: dict) -> pd.DataFrame:
    """Seed 000 Table III, paper | belief vectors | graphloc at the stated setting and the
    chosen reading: mean updates to the first commit (wrong first locks) / to the first
    correct commit (runs never correct)."""

    def m(x):
        return (
            f"{fmt(x['mean_updates_to_converge'], '.2f')} ({x['wrong_locks']}) / "
            f"{fmt(x['mean_updates_to_correct_lock'], '.2f')} ({x['never_correct']})"
        )

    rows = [
        [
            name,
            cell,
            c["paper_table_iii"],
            m(c["belief_def1"]),
            m(c["belief_def2"]),
            m(c["tracker"]),
        ]
        for name in SETTINGS
        for cell, c in runs[name]["table3"]["cells"].items()
    ]
    columns = ["setting", "cell", "paper", "belief Def. 1", "belief Def. 2", "graphloc tracker"]
    return pd.DataFrame(rows, columns=columns)


def _seed004(sw: dict) -> dict:
    rows = [
        [
            f"{x['height']:g}",
            f"{x['pitch_um']:g}",
            f"{x['offset']:g}",
            x["noise_reading"],
            dev(x["max_deviation"]),
        ]
        for x in top(
            sw["rows"],
            lambda x: (x["height"], x["pitch_um"], x["offset"], x["noise_reading"]) == S4_STATED,
        )
    ]
    std_rows = [x for x in sw["rows"] if x["noise_reading"] == "std" and x["cells"]]
    return {
        "sweep": pd.DataFrame(
            rows,
            columns=["height [m]", "pitch [um]", "offset [m]", "sigma^2 read as", "largest dev."],
        ),
        "infeasible": sum(x["infeasible"] is not None for x in sw["rows"]),
        "best_std": min((x["max_deviation"] for x in std_rows), default=None),
    }


def seed004_by_setting(runs: dict) -> pd.DataFrame:
    """Seed 004 Table 1, paper | raw P3P | graphloc at the stated and the chosen setting."""
    rows = []
    for name in SETTINGS:
        for c in runs[name]["seed004"]["cells"]:
            p, s, g = c["paper"], c["seed_baseline_raw_p3p"], c["graphloc_smoothed"]
            rows.append(
                [
                    name,
                    f"{c['focal_mm']:g} mm",
                    f"{c['noise_variance']:g}",
                    f"{p['mean']:.4f} ({p['std']:.4f})",
                    f"{s['mean']:.4f} ({s['std']:.4f})",
                    f"{g['mean']:.4f} ({g['std']:.4f})",
                    f"{g['mean'] / s['mean']:.2f}",
                ]
            )
    columns = header(
        "setting | focal | v [px^2] | paper mean (std) | seed raw P3P mean (std) | "
        "graphloc smoothed mean (std) | graphloc / seed"
    )
    return pd.DataFrame(rows, columns=columns)


def runs_tables(runs: dict) -> dict:
    """Seed 000 Tables I / III and seed 004 Table 1 at the stated and the reproducing setting
    (also docs/results.md's last section: benchmarks.render.seed_baselines_results)."""
    return {
        "t1_runs": table1_by_setting(runs),
        "t3_runs": table3_by_setting(runs),
        "s4_runs": seed004_by_setting(runs),
    }


def context(r: dict) -> dict:
    sw, runs = r["sweeps"], r["runs"]
    bounds = r.get("bounds")
    return {
        "r": r,
        "t1": _table1(sw["table1"]),
        "t3": _table3(sw["table3"]),
        "s4": _seed004(sw["seed004"]),
        **runs_tables(runs),
        "b1": table1_bounds(bounds["table1"]) if bounds else None,
        "b3": table3_bounds(bounds["table3"]) if bounds else None,
        "s1": seed001(r["seed001"]) if "seed001" in r else None,
        "s3": seed003(r["seed003"]) if "seed003" in r else None,
        "dev": dev,
        "f2": lambda x: fmt(x, ".2f"),
    }
