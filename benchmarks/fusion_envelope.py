"""`scripts/bench_fusion.py --real --envelope` (issue 16): how far graphloc's fusion keeps its
promise beyond issue 16's protocol (5 mm noise, half the points per view). The benchmark's
trials (`benchmarks.fusion_bench_real.run_real_trial`: the same view pairs, hints and
methods) on each bundled real fragment (or --fragment), under every view condition of
ENVELOPE_VIEWS (per-view Gaussian noise, kept fraction of the fragment's points); per condition
and cell, graphloc's successes, false accepts (fused, outside the success box) and refusals,
its NEES against the chi-square band, and FPFH + RANSAC + ICP's successes. Writes the JSON,
a PNG of success and false-accept rates per condition, and the markdown
(benchmarks.render.fusion_envelope):

    .venv/bin/python scripts/bench_fusion.py --real --envelope --trials 10 --seed 2000 \
        --doc docs/results_fusion_envelope.md
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from benchmarks.trials import TrialExecutor
from benchmarks.fusion_bench_real import (
    PROTOCOL_KEEP,
    PROTOCOL_NOISE_M,
    REAL_OVERLAPS,
    run_real_trial,
    summarize_real,
)
from benchmarks.real_views import BUNDLED_FRAGMENTS
from benchmarks.render import render
from graphloc.structured import dumps_json

# (noise [m], kept fraction): noisier and cleaner views than the protocol's, then sparser and
# denser ones
ENVELOPE_VIEWS = (
    (0.003, PROTOCOL_KEEP),
    (PROTOCOL_NOISE_M, PROTOCOL_KEEP),
    (0.007, PROTOCOL_KEEP),
    (0.01, PROTOCOL_KEEP),
    (PROTOCOL_NOISE_M, 0.25),
    (PROTOCOL_NOISE_M, 1.0),
)


def summarize_envelope(rows: list[dict]) -> list[dict]:
    """One entry per (fragment, noise, keep) of `rows` (`run_real_trial` rows with those three
    keys added): per cell (`summarize_real`), graphloc's trials, successes, false accepts, not
    fused, median rotation error on successes, mean NEES with its band, and FPFH's successes."""
    out = []
    keys = dict.fromkeys((r["fragment"], r["noise_m"], r["keep"]) for r in rows)
    for fragment, noise, keep in keys:
        group = [
            r for r in rows if (r["fragment"], r["noise_m"], r["keep"]) == (fragment, noise, keep)
        ]
        cells = {}
        for name, s in summarize_real(group).items():
            g = s["graphloc"]
            cells[name] = {
                "trials": s["trials"],
                "successes": g["successes"],
                "false_accepts": g["false_accepts"],
                "not_fused": g["not_fused"],
                "rot_deg_median_successes": g["rot_deg_median_successes"],
                "nees_mean": g.get("nees_mean"),
                "nees_in_band": g.get("nees_in_band"),
                "fpfh_successes": s["fpfh_ransac"]["successes"],
            }
        out.append({"fragment": fragment, "noise_m": noise, "keep": keep, "cells": cells})
    return out


CELL_COLOURS = ("C0", "C1", "C2", "C4", "C5", "C6")  # no red: red marks the false accepts


def plot_envelope(entries: list[dict], path: Path) -> None:
    """Per fragment and view condition, one bar per cell: graphloc's success rate, and its
    false-accept rate stacked on it in red (hatched)."""
    from graphloc.plots import plt  # the one place that sets the backend

    fragments = list(dict.fromkeys(e["fragment"] for e in entries))
    fig, axes = plt.subplots(1, len(fragments), figsize=(6 * len(fragments), 4), squeeze=False)
    for ax, fragment in zip(axes[0], fragments):
        es = [e for e in entries if e["fragment"] == fragment]
        names = list(es[0]["cells"])
        x, width = np.arange(len(es)), 0.8 / len(names)
        for i, name in enumerate(names):
            cells = [e["cells"][name] for e in es]
            n = np.array([c["trials"] for c in cells], dtype=float)
            ok = np.array([c["successes"] for c in cells]) / n
            fa = np.array([c["false_accepts"] for c in cells]) / n
            at = x + (i - (len(names) - 1) / 2) * width
            ax.bar(at, ok, width, color=CELL_COLOURS[i % len(CELL_COLOURS)], label=name)
            ax.bar(
                at,
                fa,
                width,
                bottom=ok,
                color="red",
                hatch="//",
                alpha=0.6,
                label="false accepts" if i == 0 else None,
            )
        ax.set_xticks(x, [f"{1000 * e['noise_m']:g} mm\nkeep {e['keep']:g}" for e in es])
        ax.set_ylim(0, 1.05)
        ax.set_ylabel("fraction of trials")
        ax.set_title(fragment)
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main_envelope(args, views=ENVELOPE_VIEWS) -> int:
    """`--real --envelope`: the benchmark's trials under every view condition of `views` on
    the bundled fragments (or args.fragment); writes the JSON and PNG to args.out and, with
    args.doc, the markdown there (its JSON and PNG beside it)."""
    fragments = [args.fragment] if args.fragment else [str(f) for f in BUNDLED_FRAGMENTS]
    jobs = [
        (ov, args.seed + i, False, fragment, noise, keep)
        for fragment in fragments
        for noise, keep in views
        for ov in REAL_OVERLAPS
        for i in range(args.trials)
    ]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    rows = []
    with TrialExecutor(args.workers) as ex:
        for job, rs in zip(jobs, ex.imap(run_real_trial, jobs, desc="view pairs")):
            tags = {"fragment": Path(job[3]).name, "noise_m": job[4], "keep": job[5]}
            rows += [dict(r, **tags) for r in rs]
    doc = Path(args.doc) if args.doc else None
    png = doc.with_suffix(".png") if doc else out / "bench_fusion_envelope.png"
    command = "python scripts/bench_fusion.py --real --envelope"
    command += f" --trials {args.trials} --seed {args.seed}"
    if args.fragment:
        command += f" --fragment {args.fragment}"
    if doc:
        command += f" --doc {doc}"
    entries = summarize_envelope(rows)
    report = {
        "benchmark": "fusion_envelope",
        "command": command,
        "trials_per_overlap": args.trials,
        "workers": args.workers,
        "cpus": os.cpu_count(),
        "wall_time_s": time.perf_counter() - start,
        "png": str(png),
        "entries": entries,
    }
    if doc:
        doc.with_suffix(".json").write_text(dumps_json(report, indent=1) + "\n")
    (out / "bench_fusion_envelope.json").write_text(dumps_json(dict(report, trials=rows), indent=1))
    plot_envelope(entries, png)
    text = render("fusion_envelope", report)
    if doc:
        doc.write_text(text)
    print(text)
    print(f"wrote {out / 'bench_fusion_envelope.json'} and {png}")
    return 0
