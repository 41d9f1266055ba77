"""The report of the map-fusion benchmark on real geometry (issue 16,
`benchmarks.fusion_bench_real`): the success bounds, the methods' order, the cells and the
scatter PNG (its markdown: benchmarks.render.fusion_real)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

TRANS_OK_M = 0.05  # [m] success: translation error below this (both protocols)
REAL_METHODS = ("graphloc", "graphloc_before", "o3d_icp", "o3d_icp_fine", "fpfh_ransac")
REAL_ROT_OK_DEG = 1.0


def _cells(rows):
    keys = sorted(
        {(r["overlap_target"], r["hint_rot_deg"], r["hint_trans_m"]) for r in rows},
        key=lambda k: (-k[0], k[1]),
    )
    return [
        (k, [r for r in rows if (r["overlap_target"], r["hint_rot_deg"], r["hint_trans_m"]) == k])
        for k in keys
    ]


def plot_real(rows: list[dict], path: Path, data: str | None = None) -> None:
    from graphloc.plots import plt  # the one place that sets the backend

    cells = _cells(rows)
    fig, axes = plt.subplots(
        1, len(cells), figsize=(4.2 * len(cells), 4.2), sharex=True, sharey=True
    )
    for ax, ((ov, rd, tm), cell) in zip(np.atleast_1d(axes), cells):
        for i, m in enumerate(REAL_METHODS):
            rot = np.maximum([r[m]["rot_deg"] for r in cell], 1e-3)
            tr = np.maximum([r[m]["trans_m"] for r in cell], 1e-4)
            acc = np.array([r[m]["accepted"] for r in cell])
            ax.scatter(rot[acc], tr[acc], s=18, color=f"C{i}", label=m, alpha=0.8)
            ax.scatter(
                rot[~acc],
                tr[~acc],
                s=30,
                color=f"C{i}",
                marker="x",
                label=f"{m} (not fused)" if (~acc).any() else None,
            )
        ax.axvline(REAL_ROT_OK_DEG, color="r", ls="--", lw=1)
        ax.axhline(TRANS_OK_M, color="r", ls="--", lw=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"overlap {ov:.0%}, hint {rd:g} deg / {100 * tm:g} cm", fontsize=9)
        ax.set_xlabel("rotation error [deg]")
        ax.grid(True, which="both", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("translation error [m]")
    np.atleast_1d(axes)[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(
        f"real fragment ({data or 'TUM RGB-D fr3 office'}): ground + flipped ceiling view; "
        "x = returned as not fused; dashed = success bounds"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
