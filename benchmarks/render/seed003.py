"""docs/results_seed003.md and results_seed003_heldout.md: seed 003 on crawler-pair, the seed's
EKF against graphloc and the ablations (benchmarks.seed003), from the doc's JSON: errors per
axis and the scale error per N and method, the max-mixture's choices, the teammate rim's
front-end errors against the Cramér-Rao bound, KLT drift by track age, the targets' checks.
Template: templates/seed003.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.render import header
from benchmarks.seed003_measures import AXES, FRONT_ENDS, METHODS


def _errors(r: dict) -> pd.DataFrame:
    rows = []
    for n in r["n_values"]:
        for m in METHODS:
            e = r["per_n"][str(n)][m]
            ax, sd = e["mean_abs_error_mm"], e["std_over_trials_mm"]
            sc = e["scale_error_max_after_3rd_sighting"]
            rows.append(
                [n, m] + [f"{ax[a]:.3f} ± {sd[a]:.3f}" for a in AXES]
                + [f"{100 * sc['mean']:.2f} % / {100 * sc['max']:.2f} %",
                   f"{sc['trials_above_2pct']} / {len(sc['per_trial'])}",
                   e["scale_below_2pct_from_frame_worst_trial"],
                   f"{100 * e['scale_error_last_frame']['mean']:.2f} %",
                   f"{e['seconds_per_sequence']:.3f}"]
            )  # fmt: skip
    columns = header(
        "N | method | x [mm] | y [mm] | z [mm] | scale err. after 3rd sighting "
        "(mean / worst) | trials with scale err. >= 2 % after 3rd sighting | scale "
        "< 2 % from frame (worst trial) | scale err. last frame | s / sequence"
    )
    return pd.DataFrame(rows, columns=columns)


def _mixture(r: dict) -> pd.DataFrame:
    rows = []
    for n in r["n_values"]:
        e = r["per_n"][str(n)]
        b, o, ev = e["batch"]["mixture"], e["online"]["mixture"], e["scale_evidence"]
        unseen = ev["unseen_displacement_at_3rd_sighting_mm"]
        rows.append([n, f"{b['genuine_active']} / {b['sightings']}",
                     f"{o['genuine_active']} / {o['sightings']}",
                     f"{ev['camera_displacement_at_3rd_sighting_mm']:.1f} mm",
                     f"{100 * ev['first_order_scale_floor_at_3rd_sighting']:.2f} %",
                     f"{unseen['mean']:.2f} / {unseen['max']:.2f} mm"])  # fmt: skip
    columns = header(
        "N | max-mixture: genuine candidate active (batch final) | (online, when "
        "the frame arrived) | camera moved at 3rd sighting | first-order scale "
        "floor there | camera displacement a circle cannot see there (mean / max)"
    )
    return pd.DataFrame(rows, columns=columns)


def _front_end(r: dict) -> pd.DataFrame:
    rows = []
    for fe in FRONT_ENDS:
        e = r["front_end"][fe]
        rows.append([fe, f"{e['frames']} ({e['failed']})",
                     f"{e['depth_error_rms_mm']:.3f} / {e['depth_error_mean_mm']:+.3f}",
                     f"{e['depth_change_sd_mm']:.3f}", f"{e['lateral_error_rms_mm']:.4f}",
                     f"{e['normal_error_median_deg']:.2f} / {e['normal_error_max_deg']:.2f}",
                     f"{e['normal_error_rms_deg']:.2f}"])  # fmt: skip
    e = r["front_end"]["crlb"]
    rows.append(["Cramér-Rao bound (known background)", e["frames"],
                 f"{e['depth_sd_rms_mm']:.3f} (sigma)", f"{e['depth_change_sd_mm']:.3f}",
                 f"{e['lateral_sd_rms_mm']:.4f}", "-", f"{e['normal_rms_deg']:.2f}"])  # fmt: skip
    columns = header(
        "teammate rim | frames (failed) | depth error rms / mean [mm] | "
        "frame-to-frame depth change sd (camera moving) [mm] | lateral error rms "
        "[mm] | genuine normal error median / max [deg] | normal error rms [deg]"
    )
    return pd.DataFrame(rows, columns=columns)


def _tracks(r: dict) -> pd.DataFrame:
    t = r["klt_track_error"]
    rows = [[f"{x['ages'][0]}-{x['ages'][1]}", x["observations"],
             f"{x['median_px']:.3f} / {x['p90_px']:.3f}"] for x in t["per_age"]]  # fmt: skip
    columns = [
        f"KLT track age [frames] (N = {t['n']})",
        "observations",
        "error vs the true projection of the track's first point, median / p90 [px]",
    ]
    return pd.DataFrame(rows, columns=columns)


def context(report: dict) -> dict:
    return {
        "r": report,
        "errors": _errors(report),
        "mixture": _mixture(report),
        "front_end": _front_end(report),
        "tracks": _tracks(report),
    }
