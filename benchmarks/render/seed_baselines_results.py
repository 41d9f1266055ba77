"""docs/results.md's last section (issue 20): paper | seed baseline | graphloc for every seed
table of docs/results_seed_baselines.json at the stated and the reproducing reading, with
each table's claim (graphloc against the seed baseline). Template:
templates/seed_baselines_results.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render.seed_baselines import runs_tables
from benchmarks.render.numbers import joined, yes_no
from benchmarks.render.seed_baselines_more import (
    S1_HEADERS,
    by_n,
    s1_numbers,
    s1_paper,
    s1_ratios,
)
from benchmarks.seed003_readings import N_VALUES, trend


def _table3_claim(cells) -> dict:
    """Wrong first locks over all cells per method; the cells where graphloc's first correct
    commit comes no later than both belief vectors'."""

    def correct(c, method):
        x = c[method]["mean_updates_to_correct_lock"]
        return float("inf") if x is None else x

    methods = ("tracker", "belief_def1", "belief_def2")
    return {
        "wrong": {m: sum(c[m]["wrong_locks"] for c in cells) for m in methods},
        "earlier": sum(
            correct(c, "tracker") <= min(correct(c, "belief_def1"), correct(c, "belief_def2"))
            for c in cells
        ),
        "cells": len(cells),
    }


def _seed003(s3: dict) -> pd.DataFrame:
    rows = [["paper", "", "not in the text", "not in the text", "yes", "yes"]]
    for name in ("stated", "reproducing"):
        run = s3["runs"][name]
        for key, method in (("ekf_cm", "seed baseline (EKF)"), ("graphloc_cm", "graphloc")):
            tx = [by_n(run[key], n)[0] for n in N_VALUES]
            tz = [by_n(run[key], n)[2] for n in N_VALUES]
            rows.append(
                [method, name, joined(tx), joined(tz), yes_no(trend(tx) > 0), yes_no(trend(tz) < 0)]
            )
    ns = " / ".join(str(n) for n in N_VALUES)
    columns = [
        "seed 003",
        "setting",
        f"T_x N = {ns} [cm]",
        f"T_z N = {ns} [cm]",
        "(a) T_x better at small N",
        "(b) T_z improves with N",
    ]
    return pd.DataFrame(rows, columns=columns)


def context(r: dict) -> dict:
    runs = r.get("runs", {})
    out = {"r": r, "s1": None, "s3": None}
    if runs:
        t1 = runs["reproducing"]["table1"]
        ratios = [
            c["graphloc_smoothed"]["mean"] / c["seed_baseline_raw_p3p"]["mean"]
            for c in runs["reproducing"]["seed004"]["cells"]
        ]
        out.update(runs_tables(runs))
        out["t1"] = {
            "trials": t1["trials"],
            "seed": t1["seed_baseline"],
            "graphloc": t1["graphloc"],
            "ahead": yes_no(
                t1["graphloc"]["success"] >= t1["seed_baseline"]["success"]
                and t1["graphloc"]["C"]["mean"] <= t1["seed_baseline"]["C"]["mean"]
            ),
        }
        out["t3"] = _table3_claim(list(runs["reproducing"]["table3"]["cells"].values()))
        out["s4"] = {"ratios": ratios, "below": sum(x < 1 for x in ratios)}
    if "seed001" in r:
        s1 = r["seed001"]
        rows = [["paper", "", *s1_paper(s1)]] + [
            [method.replace("_", " "), name, *s1_numbers(s1["runs"][name][method])]
            for name in ("stated", "reproducing")
            for method in ("seed_baseline", "graphloc")
        ]
        out["s1"] = {
            "table": pd.DataFrame(rows, columns=["seed 001", "setting", *S1_HEADERS]),
            "ratios": s1_ratios(s1),
        }
    if "seed003" in r:
        out["s3"] = {"table": _seed003(r["seed003"]), "best": r["seed003"]["choice"]["best"]}
    return out
