"""The plot of seed 001 experiment 1 and seed 003 Fig. 6 in docs/results_seed_baselines.md
(issue 20), from the dicts of benchmarks.seed001_readings.run_all and seed003_readings.run_all
that benchmarks.seed_baselines_report stores under "seed001" / "seed003" (their markdown:
benchmarks.render.seed_baselines_more)."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from benchmarks.render.seed_baselines_more import by_n
from benchmarks.seed001_truth import SCORED
from benchmarks.seed_baselines import REPRODUCE_TOL
from benchmarks.seed003_readings import FIG3_RANGE_CM, N_VALUES
from graphloc.plots import plt


def plot(r: dict, path: Path) -> None:
    """Seed 001: ours / paper per scored number at the stated and the chosen reading, seed
    baseline and graphloc; the sweep's largest deviations. Seed 003: EKF T_x and T_z vs N at
    both settings with graphloc's; the tracker's largest errors vs Fig. 3. Last panel: seed
    001 run 1's orientation std / mean vs the hand-eye axis at the chosen reading."""
    fig, axes = plt.subplots(1, 5, figsize=(23, 4.2))
    if "seed001" in r:
        s1 = r["seed001"]
        ax = axes[0]
        x = np.arange(len(SCORED))
        for i, (name, method) in enumerate(
            itertools.product(("stated", "reproducing"), ("seed_baseline", "graphloc"))
        ):
            s = s1["runs"][name][method]
            ratio = [s[run][key] / s1["paper"][run][key] for run, key in SCORED]
            ax.bar(x + 0.2 * i - 0.3, ratio, 0.2, label=f"{method.replace('_', ' ')}, {name}")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.axhspan(1 - REPRODUCE_TOL, 1 + REPRODUCE_TOL, color="k", alpha=0.1)
        labels = [
            f"{'run 1' if run == 'run1' else '3 m'} {key.rsplit('_', 1)[0]}" for run, key in SCORED
        ]
        ax.set_xticks(x, labels, fontsize=6, rotation=25)
        ax.set(yscale="log", ylabel="ours / paper")
        ax.set_title("Seed 001 exp. 1 (grey: within 10 %)", fontsize=10)
        ax.legend(fontsize=6)
        ax = axes[1]
        dev = np.sort(np.minimum(s1["max_deviations"], 1e3))
        ax.plot(dev, np.arange(1, len(dev) + 1) / len(dev))
        ax.axvline(REPRODUCE_TOL, color="k", ls="--", lw=0.8)
        ax.set(xscale="log", xlabel="largest |ours / paper - 1|", ylabel="fraction of readings")
        ax.set_title(f"Seed 001 sweep ({len(dev)} readings)", fontsize=10)
        if "why" in s1:
            ax, tilt = axes[4], s1["why"]["tilt"]
            x = [t["tilt_deg"] for t in tilt]
            ax.plot(x, [t["std_over_mean"] for t in tilt], marker="o", label="ours, run 1")
            p1 = s1["paper"]["run1"]
            ax.axhline(p1["rot_std_deg"] / p1["rot_mean_deg"], color="k", ls="--", label="paper")
            ax.set(xlabel="hand-eye axis to optical axis [deg]", ylabel="rot std / mean")
            ax.set_title("Seed 001: the hand-eye axis at the chosen reading", fontsize=10)
            ax.legend(fontsize=6)
    if "seed003" in r:
        s3 = r["seed003"]
        ax = axes[2]
        for name, style in (("stated", ":"), ("reproducing", "-")):
            run = s3["runs"][name]
            for key, label, colour in (
                ("ekf_cm", "EKF", "tab:red"),
                ("graphloc_cm", "graphloc", "tab:blue"),
            ):
                for axis, marker in ((0, "o"), (2, "s")):
                    ax.plot(
                        N_VALUES,
                        [by_n(run[key], n)[axis] for n in N_VALUES],
                        style,
                        marker=marker,
                        color=colour,
                        label=f"{label} T_{'xz'[axis // 2]}, {name}",
                    )
        ax.set(xscale="log", yscale="log", xlabel="N", ylabel="mean |error| [cm]")
        ax.set_xticks(N_VALUES, [str(n) for n in N_VALUES])
        ax.set_title("Seed 003 Fig. 6 quantities", fontsize=10)
        ax.legend(fontsize=6)
        ax = axes[3]
        coarse = [x for x in s3["rows"] if x.get("stage") == "coarse"]
        scales = sorted({x["tracker_scale"] for x in coarse})
        for i, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
            mx = [
                np.mean([x["tracker_max_cm"][i] for x in coarse if x["tracker_scale"] == s])
                for s in scales
            ]
            ax.plot(scales, mx, marker="o", color=colour, label=f"ours {'XYZ'[i]}")
            ax.axhline(FIG3_RANGE_CM[i], color=colour, ls="--", lw=0.8)
        ax.set(
            yscale="log",
            xlabel="tracker scale (0: rendered front-end)",
            ylabel="largest tracker error [cm]",
        )
        ax.set_title("Seed 003 tracker vs Fig. 3 (dashed)", fontsize=10)
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
