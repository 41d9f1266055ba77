"""docs/results.md (issue 49): every seed table -- paper | seed baseline (ours) | graphloc --
from docs/results.json, the numbers `scripts/make_results.py` (benchmarks.reproduce) computed,
one entry per table (`scripts/reproduce.py TABLE --results docs/results.md` replaces one), then
the last section from docs/results_seed_baselines.json
(benchmarks.render.seed_baselines_results). Templates: templates/results.md.j2, one
templates/results_<table>.md.j2 per table (seed 000 Tables I-III, seed 004 Table 1, seed 001
experiment 1), whose values and pandas tables `section` makes."""

from __future__ import annotations

import pandas as pd

from benchmarks.render import render
from benchmarks.render.numbers import fmt, yes_no

CAMERAS = ("C2", "C3", "C")


def _ms(x: dict, spec: str = ".3f") -> str:
    """A timing as "median ms (p95 p95)"."""
    return f"{x['median']:{spec}} ms (p95 {x['p95']:{spec}})"


def _table_i(r: dict) -> dict:
    """Seed 000 Table I (Sec. VI-A)."""
    p, s, g, n = r["paper"], r["seed_baseline"], r["graphloc"], r["trials"]
    rows = [
        [
            "success (closer to the truth than any pseudo solution)",
            f"{p['success']}/{p['trials']}",
            f"{s['success']}/{n}",
            f"{g['success']}/{n}",
        ],
        [
            f"all three positions within {r['config']['success_tol']:g} m",
            "--",
            s["within_tol"],
            g["within_tol"],
        ],
    ]

    def mean_std(x):
        return f"{fmt(x['mean'])} ({fmt(x['std'])})"

    for cam in CAMERAS:
        paper = f"{p[cam][0]:.1e} ({p[cam][1]:.1e})"
        rows.append([f"{cam} mean (std), own successes", paper, mean_std(s[cam]), mean_std(g[cam])])
    sc, gc = s["common_trials"], g["common_trials"]
    for cam in CAMERAS:
        label = f"{cam} mean (std), the {r['common_successes']} trials both got right"
        rows.append([label, "--", mean_std(sc[cam]), mean_std(gc[cam])])
    columns = [
        "quantity",
        "paper",
        "seed baseline (ours: P3P + straight-line test)",
        "graphloc (front door: the trial's log through the team graph)",
    ]
    e = r["evidence"]
    median = e["genuine_p3p_error_true_ground_median_m"]
    return {
        "table": pd.DataFrame(rows, columns=columns),
        "median": median,
        "p90": e["genuine_p3p_error_true_ground_p90_m"],
        "median_relative": median / r["config"]["scale"],
    }


def _table_ii(r: dict) -> dict:
    """Seed 000 Table II (running times on the machine that ran it): every row says what it
    times."""
    d, g, u = r["deterministic_ms"], r["deterministic_ms"]["graphloc"], r["update"]
    um, paper = u["ms"], r["paper_ms"]
    rows = [
        [
            f"deterministic, one trial ({r['samples']} trials). Seed: three-robot triangle from "
            "the mutual omni pixels, P3P on the climber's three snapshots, straight-line test. "
            "graphloc: the trial's log read (open_run), the team graph built, solved in batch "
            "(`graphloc smooth`)",
            f"{paper['deterministic']} ms",
            _ms(d["seed_baseline"], ".2f"),
            f"{_ms(g['total'], '.2f')}: read {g['read']['median']:.2f} + build "
            f"{g['build']['median']:.2f} + solve {g['solve']['median']:.2f} ms",
        ]
    ]
    if "deterministic_batched_ms" in r:
        b = r["deterministic_batched_ms"]
        rows.append(
            [
                "the same over all Table I trials, per trial (wall time). Seed: P3P + straight-"
                "line test vectorized over the trials (the triangle not included). graphloc: the "
                "whole front-door pass of Table I (logs written and read, graphs built and "
                "solved) across its worker processes",
                "--",
                f"{b['seed_baseline']:.3f} ms",
                f"{b['graphloc']:.2f} ms",
            ]
        )
    rows.append(
        [
            f"one update, K = {u['max_hypotheses']['tracker']}: one `update(candidates, "
            f"odometry)` call alone ({u['updates']} updates of {u['runs']} feng-probabilistic "
            "runs, the inputs built beforehand). Seed: belief vector Def. 1. graphloc: "
            "HypothesisTracker",
            f"{paper['update']} ms",
            _ms(um["belief_def1"]),
            _ms(um["tracker"]),
        ]
    )
    columns = [
        "algorithm: what is timed",
        "paper (Matlab, 2011)",
        "seed baseline (ours)",
        "graphloc",
    ]
    window = u.get("tracker_window_ms")
    c = r["bearing_custom_factor_linearize"]
    return {
        "table": pd.DataFrame(rows, columns=columns),
        "u": u,
        "ms": {name: _ms(x) for name, x in um.items()},
        "write_ms": g["write"]["median"],
        "window": None
        if window is None
        else {
            "ms": _ms(window),
            "mean": window["mean"],
            "beyond_belief": window["median"] > um["belief_def1"]["median"],
        },
        "custom_us": 1e6 * c["custom_s"],
        "builtin_us": 1e6 * c["builtin_s"],
        "ratio": c["ratio"],
    }


def _table_iii(r: dict) -> dict:
    """Seed 000 Table III (Sec. VI-B): mean updates to the first lock (wrong first locks /
    never converged), then to the first correct lock (runs never correct)."""
    methods = ("belief_def1", "belief_def2", "particle_filter", "tracker", "front_door")

    def first(x):
        mean = fmt(x["mean_updates_to_converge"], ".2f")
        return f"{mean} ({x['wrong_locks']}/{x['never_converged']})"

    def correct(x):
        return f"{fmt(x['mean_updates_to_correct_lock'], '.2f')} ({x['never_correct']})"

    def rows(cell, fewer):
        return [
            [name, c["paper_table_iii"], *(cell(c[m]) for m in methods), yes_no(fewer[name])]
            for name, c in r["cells"].items()
        ]

    engine = ["graphloc HypothesisTracker (engine)", "graphloc (front door)"]
    fewer = "graphloc fewer than paper and belief"
    converge = ["cell", "paper", "seed baseline (ours): belief Def. 1", "belief Def. 2"]
    converge += ["particle filter (seed 004)", *engine, fewer]
    lock = ["cell", "paper", "belief Def. 1", "belief Def. 2", "particle filter", *engine, fewer]
    return {
        "runs": r["config"]["runs"],
        "converge": pd.DataFrame(
            rows(first, r["graphloc_fewer_updates_than_paper_and_belief"]), columns=converge
        ),
        "correct": pd.DataFrame(
            rows(correct, r["graphloc_fewer_updates_to_correct_lock_than_paper_and_belief"]),
            columns=lock,
        ),
    }


def _seed004(r: dict) -> dict:
    """Seed 004 Table 1 (Sec. III)."""

    def rms_mean_std(x):
        return f"{x['rms']:.4f} / {x['mean']:.4f} ({x['std']:.4f})"

    rows = [
        [
            f"{c['focal_mm']:g} mm",
            f"{c['noise_variance']:g}",
            f"{c['paper']['mean']:.4f} ({c['paper']['std']:.4f})",
            rms_mean_std(c["seed_baseline_raw_p3p"]),
            rms_mean_std(c["graphloc_smoothed"]),
            f"{c['graphloc_placed_runs']} / {c['runs']}",
        ]
        for c in r["cells"]
    ]
    columns = ["focal", "noise var [px^2]", "paper mean (std)"]
    columns += ["seed baseline raw P3P: RMS / mean (std)"]
    columns += ["graphloc (front door): RMS / mean (std)", "runs placed"]
    return {"table": pd.DataFrame(rows, columns=columns), "first": r["cells"][0]}


def _seed001(r: dict) -> dict:
    """Seed 001 experiment 1 (Sec. V-A): the paper's rows beside the simulated variants."""
    quantities = ("pos_mean", "pos_std", "pos_max", "rot_mean", "rot_std", "rot_max")

    def cell(s, quantity):
        key, unit = (f"{quantity}_cm", "cm") if quantity[0] == "p" else (f"{quantity}_deg", "deg")
        return f"{s[key]:.2f} {unit}" if key in s else "n/a"

    def paper(p, quantity):
        key = f"{quantity}_cm" if quantity[0] == "p" else f"{quantity}_deg"
        return f"{p[key]} {key.rsplit('_', 1)[1]}" if key in p else "-"

    rows = []
    labels = (
        ("run1", "1 (0.68-1.74 m)"),
        ("run2_at_3m", "2 (>= 2.8 m)"),
        ("run2_all", "2 (1-3 m)"),
    )
    for key, label in labels:
        if key in r["paper"]:
            rows.append([label, "paper", "-", *(paper(r["paper"][key], q) for q in quantities)])
        for variant, s in r["summary"][key].items():
            localized = f"{s['localized']}/{s['frames']}"
            rows.append([label, f"sim {variant}", localized, *(cell(s, q) for q in quantities)])
    columns = ["run", "pose", "frames localized", "pos mean", "pos std", "pos max"]
    columns += ["rot mean", "rot std", "rot max"]
    return {"table": pd.DataFrame(rows, columns=columns)}


SECTIONS = {
    "seed000-table1": _table_i,
    "seed000-table2": _table_ii,
    "seed000-table3": _table_iii,
    "seed004-table1": _seed004,
    "seed001-exp1": _seed001,
}


def section(name: str, entry: dict) -> dict:
    """The template values of one table's entry of docs/results.json: its result `r`, the
    values and tables of SECTIONS[name], `command` (the re-run of this table alone, or None:
    the page's run) and its template."""
    return {
        "name": name,
        "template": f"results_{name.replace('-', '_')}.md.j2",
        "r": entry["result"],
        "command": entry.get("command"),
        **SECTIONS[name](entry["result"]),
    }


def context(results: dict, seed_baselines: dict) -> dict:
    """docs/results.json's run and its tables in the order of SECTIONS, then the rendered last
    section (docs/results_seed_baselines.json)."""
    entries = results["sections"]
    return {
        "run": results["run"],
        "sections": {name: section(name, entries[name]) for name in SECTIONS if name in entries},
        "seed_baselines": render("seed_baselines_results", seed_baselines),
    }
