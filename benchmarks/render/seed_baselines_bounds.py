"""The seed 000 bounds of docs/results_seed_baselines.md (benchmarks.seed_baselines_bounds,
bounds_t3): Table I's numbers as disjoint intervals of image std, Table III's genuine track
lost by the image noise. Values and tables for templates/seed_baselines.md.j2."""

from __future__ import annotations

import numpy as np
import pandas as pd

from benchmarks.render import header

T1_LABELS = {
    "correct": "correct /1000",
    "C2_mean": "C2 mean",
    "C2_std": "C2 std",
    "C3_mean": "C3 mean",
    "C3_std": "C3 std",
    "C_mean": "C mean",
    "C_std": "C std",
    "line_genuine_mean": "genuine line mean",
    "line_genuine_max": "genuine line max",
    "line_second_mean": "runner-up mean",
}


def _g(x: float) -> str:
    return "inf" if not np.isfinite(x) else f"{x:.3g}"


def _bracket(v: dict | None) -> str:
    """The outer bracket (open) that holds the true interval; "none" if no grid point meets."""
    return "none" if v is None else f"({_g(v['outer_lo'])}, {_g(v['outer_hi'])})"


def _proof(d: dict | None, labels: dict) -> str:
    if d is None:
        return "brackets overlap"
    if "empty" in d:
        return "never met: " + ", ".join(labels.get(k, k) for k in d["empty"])
    return (
        f"{labels.get(d['ends_first'], d['ends_first'])} needs < {_g(d['below'])}, "
        f"{labels.get(d['starts_last'], d['starts_last'])} > {_g(d['above'])} "
        f"(x{d['ratio']:.1f})"
    )


def table1_bounds(b: dict) -> dict:
    readings = b["readings"]
    rows = [
        [f"{x['lateral_sigma']:g}", x["orientation"]]
        + [_bracket(x["intervals"][k]) for k in T1_LABELS]
        + [_proof(x["disjoint_correct_vs_C_mean"], T1_LABELS)]
        for x in readings
    ]
    pairs = [x["disjoint_correct_vs_C_mean"] for x in readings]
    return {
        "b": b,
        "brackets": pd.DataFrame(
            rows, columns=["lateral [m]", "orientation", *T1_LABELS.values(), "proof"]
        ),
        "ratios": [d["ratio"] for d in pairs if d and "ratio" in d],
        "never": sum(1 for d in pairs if d and "empty" in d),
        "monotone": sum(x["monotone"]["correct"] == "decreasing" for x in readings),
        "disjoint": sum(x["disjoint"] is not None for x in readings),
        "never_met": [
            T1_LABELS[k] for k in T1_LABELS if all(x["intervals"][k] is None for x in readings)
        ],
    }


def _mono_summary(monotone: dict) -> str:
    dec = sum(v == "decreasing" for v in monotone.values())
    inc = sum(v == "increasing" for v in monotone.values())
    return f"{dec} cells falling, {inc} rising, {len(monotone) - dec - inc} neither"


def table3_bounds(b: dict) -> dict:
    tr = b["traces"]
    sig = tr["sigmas"]
    first_cells = tr["by_sigma"][0]["cells"]
    cells = list(first_cells)
    traces = pd.DataFrame(
        [
            [f"{x['pixel_sigma']:g}"]
            + [
                f"{c['runs_lost']} / {c['runs_jumped']}, {c['updates_bound']:.1f}"
                for c in x["cells"].values()
            ]
            + [
                x["runs_lost"],
                f"{x['cells_bound_exceeds_paper']} / {x['cells_bound_left_exceeds_paper']}",
            ]
            for x in tr["by_sigma"]
        ],
        columns=["image std [px]"]
        + [f"{c} ({first_cells[c]['paper']:g})" for c in cells]
        + [
            f"runs lost (of {tr['runs']})",
            "cells with bound > paper + 10 % (lost / lost or jumped)",
        ],
    )
    noise_free = pd.DataFrame(
        [
            [
                name,
                c["frames"],
                ", ".join(map(str, c["jump_frames"])) or "-",
                c["ambiguous_frames"],
                "-"
                if c["ambiguous_margin_min_m"] is None
                else f"{c['ambiguous_margin_min_m']:.4f}",
                c["merge_frames"],
                c["size_changes"],
                f"{c['closest_pair_m']:.4f}",
            ]
            for name, c in tr["noise_free"].items()
        ],
        columns=header(
            "cell | frames | jump frames | ambiguous frames | smallest margin [m] | "
            "frames with two candidates within the gate | set size changes | closest pair [m]"
        ),
    )
    all_cells = [x["pixel_sigma"] for x in tr["by_sigma"] if x["cells_bound_exceeds_paper"] == 6]
    below = [i for i, s in enumerate(sig) if not all_cells or s < min(all_cells)]
    readings = pd.DataFrame(
        [
            [
                x["odometry_model"],
                x["likelihood"],
                x["action_frame"],
                _bracket(x["intervals"]["no_relocalization"]),
                _bracket(x["intervals"]["no_wrong_lock"]),
            ]
            + [_bracket(x["intervals"][c]) for c in cells]
            + [
                _mono_summary(x["monotone"]),
                _proof(x["disjoint"], {}),
                max((x["cells_met"][i] for i in below), default=0),
            ]
            for x in b["readings"]
        ],
        columns=[
            "odometry",
            "likelihood",
            "action frame",
            "no relocalization",
            "no wrong lock",
            *cells,
            "mean updates vs std",
            "proof",
            "cells met below the bound's std",
        ],
    )
    positive = [x for x in tr["by_sigma"] if x["pixel_sigma"] > 0]
    zero = [x for x in b["rows"] if x["pixel_sigma"] == 0.0]
    # the paper's slowest cell, and the readings where it is the slowest without image noise
    paper = {n: c["paper"] for n, c in first_cells.items()}
    slowest = max(paper, key=paper.get)
    agree = 0
    for x in b["readings"]:
        m0 = {c: v[0] for c, v in x["mean_updates"].items() if v[0] is not None}
        agree += bool(m0) and max(m0, key=m0.get) == slowest
    return {
        "b": b,
        "tr": tr,
        "traces": traces,
        "noise_free": noise_free,
        "readings": readings,
        "all_cells": all_cells,
        "first": positive[0] if positive else None,
        "zero": zero,
        "zero_relocalized": sum(x["runs_with_relocalization"] for x in zero),
        "zero_wrong": sum(x["wrong_locks"] for x in zero),
        "below": [sig[i] for i in below],
        "proven": sum(x["disjoint"] is not None for x in b["readings"]),
        "most": max(max((x["cells_met"][i] for i in below), default=0) for x in b["readings"]),
        "slowest": slowest,
        "slowest_paper": paper[slowest],
        "slowest_agree": agree,
    }
