"""The plots of seed 000's bounds in docs/results_seed_baselines.md (issue 20), from the dict
benchmarks.seed_baselines_report stores under "bounds" (benchmarks.seed_baselines_bounds,
bounds_t3; their markdown: benchmarks.render.seed_baselines_bounds)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.render.seed_baselines_bounds import T1_LABELS
from benchmarks.seed_baselines import REPRODUCE_TOL
from graphloc.plots import plt

T1_PNG = "results_seed_baselines_t1_intervals.png"
T3_PNG = "results_seed_baselines_t3_bounds.png"


def plot_table1(b: dict, path: Path) -> None:
    """One panel per geometric reading: per number the bracket (thin) and the grid points
    that meet the band (thick), x = image std on a log axis."""
    readings = b["readings"]
    fig, axes = plt.subplots(2, (len(readings) + 1) // 2, figsize=(18, 7.5), sharex=True)
    keys = list(T1_LABELS)
    lo_x = b["sigmas"][0] / 2
    hi_x = b["sigmas"][-1] * 2
    for ax, x in zip(axes.ravel(), readings):
        for i, k in enumerate(keys):
            v = x["intervals"][k]
            y = len(keys) - 1 - i
            if v is None:
                ax.text(lo_x * 1.2, y, "never", va="center", fontsize=7, color="grey")
                continue
            a, c = max(v["outer_lo"], lo_x), min(v["outer_hi"], hi_x)
            ax.plot([a, c], [y, y], color="tab:blue", lw=1)
            ax.plot([v["lo"], v["hi"]], [y, y], color="tab:blue", lw=5)
        ax.set_yticks(range(len(keys)), [T1_LABELS[k] for k in reversed(keys)], fontsize=7)
        ax.set_xscale("log")
        ax.set_xlim(lo_x, hi_x)
        ax.axvline(0.5, color="k", ls=":", lw=0.8)
        ax.set_title(f"lateral {x['lateral_sigma']:g} m, {x['orientation']}", fontsize=9)
        ax.set_xlabel("image std [px]")
    fig.suptitle(
        "Seed 000 Table I: image stds where each number meets the paper within "
        f"{100 * REPRODUCE_TOL:.0f} % (thick: grid points, thin: bracket; dotted: stated 0.5 px)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_table3(b: dict, path: Path) -> None:
    """Runs losing the genuine trace and relocalized runs per reading vs image std; the bound
    on mean updates to converge / paper per cell; mean updates / paper of one reading."""
    tr = b["traces"]
    sig = np.asarray(tr["sigmas"], dtype=float)
    fig, axes = plt.subplots(1, 3, figsize=(17, 4.5))
    ax = axes[0]
    for x in b["readings"]:
        ax.plot(sig, x["relocalized_runs"], color="grey", lw=0.6, alpha=0.6)
    ax.plot([], [], color="grey", lw=0.6, label="relocalized runs, each belief reading")
    ax.plot(sig, [x["runs_lost"] for x in tr["by_sigma"]], "k-o", ms=4, label="genuine lost")
    ax.plot(
        sig, [x["runs_with_event"] for x in tr["by_sigma"]], "k:s", ms=3, label="lost or jumped"
    )
    ax.set(ylabel=f"runs (of {tr['runs']})", title="genuine trace lost vs relocalizations")
    ax.legend(fontsize=7)
    ax = axes[1]
    for cell in tr["by_sigma"][0]["cells"]:
        ratio = [
            x["cells"][cell]["updates_bound"] / x["cells"][cell]["paper"] for x in tr["by_sigma"]
        ]
        ax.plot(sig, ratio, marker="o", ms=3, label=cell)
    ax.axhline(1 + REPRODUCE_TOL, color="k", ls="--", lw=0.8)
    ax.set(yscale="log", ylabel="bound on mean updates / paper")
    ax.set_title("no relocalization => updates >= bound (dashed: paper + 10 %)", fontsize=9)
    ax.legend(fontsize=6)
    ax = axes[2]
    for x in b["readings"]:
        if (x["likelihood"], x["action_frame"], x["odometry_model"]) != (
            "inner_product",
            "solution",
            "per_axis",
        ):
            continue
        for cell, mean in x["mean_updates"].items():
            paper = tr["by_sigma"][0]["cells"][cell]["paper"]
            ax.plot(
                sig,
                [np.nan if v is None else v / paper for v in mean],
                marker="o",
                ms=3,
                label=cell,
            )
    ax.axhspan(1 - REPRODUCE_TOL, 1 + REPRODUCE_TOL, color="k", alpha=0.1)
    ax.set(ylabel="mean updates to converge / paper", yscale="log")
    ax.set_title("belief inner_product, solution, per_axis (grey: within 10 %)", fontsize=9)
    ax.legend(fontsize=6)
    for a in axes:
        a.set_xscale("symlog", linthresh=sig[sig > 0].min())
        a.set_xlim(0.0, 1.5 * sig.max())
        a.set_xlabel("image std [px] (symlog: 0 = noise-free)")
    fig.suptitle(
        "Seed 000 Table III: the genuine track and the belief vector from zero image noise up"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot(b: dict, directory: Path) -> None:
    plot_table1(b["table1"], Path(directory) / T1_PNG)
    plot_table3(b["table3"], Path(directory) / T3_PNG)
