"""docs/results_fusion_real.md and _redwood.md: the map-fusion benchmark on real geometry
(benchmarks.fusion_bench_real, issue 16) from its JSON summary, and the covariance
calibration (docs/results_fusion_calibration.json) it was scored with. Template:
templates/fusion_real.md.j2."""

from __future__ import annotations

import pandas as pd

from graphloc.mapping.registration import RegistrationConfig
from benchmarks.fusion_report_real import REAL_METHODS

STAGES = ("coarse_s", "fine_s", "checks_s", "polish_s", "rest_s")


def _success(c: dict, s: dict) -> str:
    """successes / trials [false accepts] {not fused}"""
    text = f"{c['successes']}/{s['trials']} [{c['false_accepts']}]"
    return text + (f" {{{c['not_fused']}}}" if c["not_fused"] else "")


def _error_time(c: dict, s: dict) -> str:
    """median rotation [deg] / translation [cm] on successes, median seconds"""
    err = (
        f"{c['rot_deg_median_successes']:.3f} / {100 * c['trans_m_median_successes']:.2f}"
        if c["successes"]
        else "—"
    )
    t = f"{c['seconds_median']:.2f} s" if c["seconds_median"] is not None else "—"
    return f"{err}, {t}"


def _stages(st: dict | None) -> str:
    """median seconds per stage; starts, fine stages, polish rounds"""
    if not st:
        return "—"
    secs = " / ".join(f"{st[k]:.2f}" for k in STAGES)
    return f"{secs}; {st['starts']:g}, {st['fine_stages']:g}, {st['polish_rounds']:g}"


def _per_method(summary: dict, cell) -> pd.DataFrame:
    """One row per method, one column per cell of the summary."""
    rows = [[m] + [cell(s[m], s) for s in summary.values()] for m in REAL_METHODS]
    return pd.DataFrame(rows, columns=["method", *summary])


def _signed(mean: float, std: float, scale: float, digits: int) -> str:
    return f"{mean * scale:+.{digits}f} +- {std * scale:.{digits}f}"


def context(report: dict, calibration: dict) -> dict:
    summary = report["summary"]
    cells = summary.values()
    last = [s["last_stage_from_truth"] for s in cells]
    extra = {
        "graphloc's last stage from the true pose (all trials)": [
            f"{x['rot_deg_median']:.3f} / {100 * x['trans_m_median']:.2f}" for x in last
        ],
        "Cramer-Rao bound of the two views, the surface known (rotation)": [
            f"{x['bound_rot_deg_median']:.3f} / —" for x in last
        ],
        "graphloc time / fpfh_ransac time (medians, same run)": [
            f"{s['graphloc_vs_fpfh_time_ratio']:.2f}x" for s in cells
        ],
        "graphloc's own preparation per view pair, beyond the denoising and normals every "
        "method shares (the scans' residual spread), median [s]; (graphloc + it) / "
        "fpfh_ransac time": [
            f"{s['graphloc_own_prepare_s_median']:.2f} s; "
            f"{s['graphloc_with_own_prepare_vs_fpfh_time_ratio']:.2f}x"
            for s in cells
        ],
        "graphloc's stages, median [s]: coarse / fine / checks / polish / rest; starts, "
        "fine stages, polish rounds (`RegistrationDecision.timings`)": [
            _stages(s["graphloc"].get("stages_median")) for s in cells
        ],
    }
    errors = pd.concat(
        [
            _per_method(summary, _error_time),
            pd.DataFrame([[k, *v] for k, v in extra.items()], columns=["method", *summary]),
        ]
    )
    bound = pd.DataFrame(
        [
            [
                name,
                " / ".join(
                    f"{v:.3f}" for v in s["last_stage_from_truth"]["bound_rot_sigma_deg_rms"]
                ),
                " / ".join(f"{v:.3f}" for v in s["graphloc"]["signed_error_std"][:3])
                if s["graphloc"].get("signed_error_std")
                else "—",
            ]
            for name, s in summary.items()
        ],
        columns=["cell", "bound rot x / y / z", "graphloc std rot x / y / z"],
    )
    nees = pd.DataFrame(
        [
            [
                name,
                f"{g['nees_mean']:.1f}",
                "{:.2f}-{:.2f}".format(*g["nees_band_95"]),
                "yes" if g["nees_in_band"] else "no",
            ]
            for name, s in summary.items()
            if "nees_mean" in (g := s["graphloc"])
        ],
        columns=["cell", "mean NEES", "95% band", "in band"],
    )
    signed = pd.DataFrame(
        [
            [name]
            + [
                _signed(m, d, 1.0, 3)
                for m, d in zip(g["signed_error_mean"][:3], g["signed_error_std"][:3])
            ]
            + [
                _signed(m, d, 1000.0, 2)
                for m, d in zip(g["signed_error_mean"][3:], g["signed_error_std"][3:])
            ]
            for name, s in summary.items()
            if "signed_error_mean" in (g := s["graphloc"])
        ],
        columns=["cell", "rot x", "rot y", "rot z", "trans x", "trans y", "trans z"],
    )
    fragment = report.get("fragment")
    return {
        "report": report,
        "data": f"`{fragment}`"
        if fragment
        else "`tests/data/real_room` (TUM RGB-D fr3 office, CC BY 4.0)",
        "successes": _per_method(summary, _success),
        "errors": errors,
        "bound": bound,
        "nees": nees,
        "signed": signed,
        "block_m": RegistrationConfig().covariance_block,
        "calibration": calibration,
    }
