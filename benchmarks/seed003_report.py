"""Seed 003 (003_8db27855ce2d5f68.txt) benchmark output: the markdown tables
(docs/results_seed003.md) and the plots of benchmarks.seed003's summary."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.seed003_measures import AXES, FRONT_ENDS, METHODS
from graphloc.plots import plt

METHOD_NOTE = (
    "ekf = the seed's EKF (eq. 13 state, proper covariance settings); batch / online = graphloc "
    "(Session LM / iSAM2, circle candidates as a max-mixture, refined rim); batch_centre = the "
    "candidates' centres moment-matched into one Gaussian; batch_crossings = batch on the seed's "
    "edge-crossing rim; batch_crlb_circle = batch with the circle drawn at the Cramér-Rao bound of "
    "each image (known background) and told that covariance: what a circle front-end at the bound "
    "would give; batch_exact_circle = batch with the exact circle, told it is exact. Errors are "
    "mean absolute per axis over the sequence (mean ± std over trials); the scale error at frame k "
    "is |s - 1|, s the least-squares ratio of the estimated to the true camera displacement lengths"
    " from frame 0, using only frames 0..k."
)


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


def markdown(result: dict, n_values: list[int]) -> str:
    lines = [
        "| N | method | x [mm] | y [mm] | z [mm] | scale err. after 3rd sighting (mean / worst) | "
        "trials with scale err. >= 2 % after 3rd sighting | "
        "scale < 2 % from frame (worst trial) | scale err. last frame | s / sequence |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n in n_values:
        for m in METHODS:
            e = result["per_n"][n][m]
            ax = e["mean_abs_error_mm"]
            sd = e["std_over_trials_mm"]
            sc = e["scale_error_max_after_3rd_sighting"]
            lines.append(
                f"| {n} | {m} | {ax['x']:.3f} ± {sd['x']:.3f} | {ax['y']:.3f} ± {sd['y']:.3f} | "
                f"{ax['z']:.3f} ± {sd['z']:.3f} | {100 * sc['mean']:.2f} % / "
                f"{100 * sc['max']:.2f} % | "
                f"{sc['trials_above_2pct']} / {len(sc['per_trial'])} | "
                f"{e['scale_below_2pct_from_frame_worst_trial']} | "
                f"{100 * e['scale_error_last_frame']['mean']:.2f} % | "
                f"{e['seconds_per_sequence']:.3f} |"
            )
    lines.append("")
    lines.append(
        "| N | max-mixture: genuine candidate active (batch final) | (online, when the frame "
        "arrived) | "
        "camera moved at 3rd sighting | first-order scale floor there | "
        "camera displacement a circle cannot see there (mean / max) |"
    )
    lines.append("|---|---|---|---|---|---|")
    for n in n_values:
        e = result["per_n"][n]
        b, o, ev = e["batch"]["mixture"], e["online"]["mixture"], e["scale_evidence"]
        lines.append(
            f"| {n} | {b['genuine_active']} / {b['sightings']} | {o['genuine_active']} / "
            f"{o['sightings']} | "
            f"{ev['camera_displacement_at_3rd_sighting_mm']:.1f} mm | "
            f"{100 * ev['first_order_scale_floor_at_3rd_sighting']:.2f} % | "
            f"{ev['unseen_displacement_at_3rd_sighting_mm']['mean']:.2f} / "
            f"{ev['unseen_displacement_at_3rd_sighting_mm']['max']:.2f} mm |"
        )
    lines.append("")
    lines.append(
        "| teammate rim | frames (failed) | depth error rms / mean [mm] | frame-to-frame depth "
        "change sd "
        "(camera moving) [mm] | lateral error rms [mm] | genuine normal error median / max [deg] | "
        "normal error rms [deg] |"
    )
    lines.append("|---|---|---|---|---|---|---|")
    for fe in FRONT_ENDS:
        e = result["front_end"][fe]
        lines.append(
            f"| {fe} | {e['frames']} ({e['failed']}) | {e['depth_error_rms_mm']:.3f} / "
            f"{e['depth_error_mean_mm']:+.3f} | {e['depth_change_sd_mm']:.3f} | "
            f"{e['lateral_error_rms_mm']:.4f} | "
            f"{e['normal_error_median_deg']:.2f} / {e['normal_error_max_deg']:.2f} | "
            f"{e['normal_error_rms_deg']:.2f} |"
        )
    e = result["front_end"]["crlb"]
    lines.append(
        f"| Cramér-Rao bound (known background) | {e['frames']} | {e['depth_sd_rms_mm']:.3f} "
        "(sigma) | "
        f"{e['depth_change_sd_mm']:.3f} | {e['lateral_sd_rms_mm']:.4f} | - | "
        f"{e['normal_rms_deg']:.2f} |"
    )
    lines.append("")
    t = result["klt_track_error"]
    lines.append(
        f"| KLT track age [frames] (N = {t['n']}) | observations | error vs the true projection "
        "of the "
        "track's first point, median / p90 [px] |"
    )
    lines.append("|---|---|---|")
    for row in t["per_age"]:
        lines.append(
            f"| {row['ages'][0]}-{row['ages'][1]} | {row['observations']} | "
            f"{row['median_px']:.3f} / "
            f"{row['p90_px']:.3f} |"
        )
    lines.append("")
    for k, v in result["checks"].items():
        lines.append(f"- {'PASS' if v else 'FAIL'}: {k}")
    return "\n".join(lines) + "\n"
