"""Seed 003 (003_8db27855ce2d5f68.txt) benchmark output: the plots of benchmarks.seed003's
summary (its markdown: benchmarks.render.seed003)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.seed003_measures import AXES, METHODS
from graphloc.plots import plt


def write_plots(summary: dict, n_values: list[int], out: Path) -> None:
    colours = {
        "ekf": "tab:red",
        "batch": "tab:blue",
        "online": "tab:green",
        "batch_centre": "tab:gray",
        "batch_crossings": "tab:orange",
        "batch_crlb_circle": "tab:brown",
        "batch_exact_circle": "tab:purple",
    }
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    width = 0.8 / len(METHODS)
    for i, axis in enumerate(AXES):
        ax = axes[i]
        for j, m in enumerate(METHODS):
            vals = [summary[n][m]["mean_abs_error_mm"][axis] for n in n_values]
            errs = [summary[n][m]["std_over_trials_mm"][axis] for n in n_values]
            offset = (j - (len(METHODS) - 1) / 2) * width
            ax.bar(
                np.arange(len(n_values)) + offset, vals, width, yerr=errs, label=m, color=colours[m]
            )
        ax.set_xticks(np.arange(len(n_values)), [f"N={n}" for n in n_values])
        ax.set_yscale("log")
        ax.set_title(f"mean |T_{axis} error| [mm]")
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(out / "axis_errors.png", dpi=120)
    plt.close(fig)

    fig, axes = plt.subplots(len(n_values), 3, figsize=(13, 2.6 * len(n_values)), squeeze=False)
    for r, n in enumerate(n_values):
        for i, axis in enumerate(AXES):
            ax = axes[r, i]
            for m in METHODS:
                curve = np.array(summary[n][m]["curve_mm"])[:, i]
                ax.plot(curve, marker=".", label=m, color=colours[m])
            ax.set_yscale("log")
            ax.set_title(f"N={n}: |T_{axis} error| [mm] vs frame", fontsize=9)
    axes[0, 0].legend()
    fig.tight_layout()
    fig.savefig(out / "error_curves.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4))
    for n in n_values:
        for m, style in (
            ("batch", "-"),
            ("online", "--"),
            ("batch_crossings", ":"),
            ("batch_crlb_circle", "-."),
        ):
            curve = np.array(summary[n][m]["scale_curve"][1:], dtype=float)
            ax.plot(np.arange(1, len(curve) + 1), 100 * curve, style, label=f"{m} N={n}")
    ax.axhline(2.0, color="k", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("frame")
    ax.set_ylabel("trajectory scale error [%] (mean over trials)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(out / "scale_error.png", dpi=120)
    plt.close(fig)
