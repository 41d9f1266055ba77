"""The seed 001 experiment 1 report (benchmarks.seed001): the paper's numbers
(001_0f8f8dae37ce6b79.txt Sec. V-A), the error table beside them and the error-vs-distance
plot."""

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


def markdown(summary: dict) -> str:
    """The error table (paper rows next to the simulated variants) of a `summary` from `main`."""

    def cell(s, key, unit):
        return f"{s[key]:.2f} {unit}" if key in s else "n/a"

    p = PAPER["run1"]
    lines = [
        "| run | pose | frames localized | pos mean | pos std | pos max "
        "| rot mean | rot std | rot max |",
        "|---|---|---|---|---|---|---|---|---|",
        f"| 1 (0.68-1.74 m) | paper | - | {p['pos_mean_cm']} cm | {p['pos_std_cm']} cm | "
        f"{p['pos_max_cm']} cm | "
        f"{p['rot_mean_deg']} deg | {p['rot_std_deg']} deg | {p['rot_max_deg']} deg |",
    ]
    for key, label in (
        ("run1", "1 (0.68-1.74 m)"),
        ("run2_at_3m", "2 (>= 2.8 m)"),
        ("run2_all", "2 (1-3 m)"),
    ):
        if key == "run2_at_3m":
            q = PAPER["run2_at_3m"]
            lines.append(
                f"| {label} | paper | - | {q['pos_mean_cm']} cm | - | - | "
                f"{q['rot_mean_deg']} deg | - | - |"
            )
        for v in VARIANTS:
            s = summary[key][v]
            lines.append(
                f"| {label} | sim {v} | {s['localized']}/{s['frames']} | "
                f"{cell(s, 'pos_mean_cm', 'cm')} | "
                f"{cell(s, 'pos_std_cm', 'cm')} | {cell(s, 'pos_max_cm', 'cm')} | "
                f"{cell(s, 'rot_mean_deg', 'deg')} | "
                f"{cell(s, 'rot_std_deg', 'deg')} | {cell(s, 'rot_max_deg', 'deg')} |"
            )
    return "\n".join(lines)
