"""The seed 001 experiment 1 report (benchmarks.seed001): the paper's numbers
(001_0f8f8dae37ce6b79.txt Sec. V-A) and the error-vs-distance plot (the error table beside the
paper's numbers: benchmarks.render.results)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from graphloc.plots import plt

# Sec. V-A: run 1 (moved by hand) and run 2 at about 3 m (flown)
PAPER = {
    "run1": {
        "pos_mean_cm": 1.5,
        "pos_std_cm": 0.7,
        "pos_max_cm": 12.2,
        "rot_mean_deg": 1.2,
        "rot_std_deg": 0.4,
        "rot_max_deg": 4.5,
        "distance_m": [0.677, 1.741],
    },
    "run2_at_3m": {"pos_mean_cm": 2.2, "rot_mean_deg": 1.0},
}

# p3p: the seed's pose (P3P + fourth-marker check); refined: polished on all four markers
VARIANTS = ("p3p", "refined")


def plot(runs: dict, path: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for (name, rows), colour in zip(runs.items(), ("tab:blue", "tab:orange")):
        for variant, marker in zip(VARIANTS, ("x", ".", "+")):
            pts = [
                (r["distance_m"], r[variant]["pos_err_cm"], r[variant]["rot_err_deg"])
                for r in rows
                if r.get(variant)
            ]
            if not pts:
                continue
            d, p, a = np.array(pts).T
            axes[0].scatter(
                d, p, s=8, marker=marker, color=colour, alpha=0.6, label=f"{name} {variant}"
            )
            axes[1].scatter(
                d, a, s=8, marker=marker, color=colour, alpha=0.6, label=f"{name} {variant}"
            )
    axes[0].axhline(
        PAPER["run1"]["pos_mean_cm"], color="k", ls="--", lw=1, label="paper run 1 mean"
    )
    axes[0].axhline(
        PAPER["run2_at_3m"]["pos_mean_cm"], color="gray", ls=":", lw=1, label="paper 3 m mean"
    )
    axes[1].axhline(PAPER["run1"]["rot_mean_deg"], color="k", ls="--", lw=1)
    axes[1].axhline(PAPER["run2_at_3m"]["rot_mean_deg"], color="gray", ls=":", lw=1)
    axes[0].set(xlabel="camera-target distance [m]", ylabel="position error [cm]", yscale="log")
    axes[1].set(xlabel="camera-target distance [m]", ylabel="orientation error [deg]", yscale="log")
    axes[0].legend(fontsize=7)
    fig.suptitle("seed 001 experiment 1 in simulation (752x480, 90 deg FOV, larger target)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
