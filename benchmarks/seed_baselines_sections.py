"""docs/results_seed_baselines.md sections, plot and docs/results.md rows for seed 001
experiment 1 and seed 003 Fig. 6 (issue 20), from the dicts of
benchmarks.seed001_readings.run_all and seed003_readings.run_all that
benchmarks.seed_baselines_report stores under "seed001" / "seed003". Every number
printed is one of the dicts'."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from benchmarks.markdown import fmt
from benchmarks.seed001_readings import STATED
from benchmarks.seed001_report import s1_why
from benchmarks.seed001_truth import SCORED
from benchmarks.seed_baselines import REPRODUCE_TOL
from benchmarks.seed003_readings import (
    FEATURE_SIGMAS,
    FIG3_RANGE_CM,
    N_VALUES,
    TILT_DEG,
)
from graphloc.plots import plt

S1_COLUMNS = (
    ("focal_error", "focal err.", lambda x: f"{100 * x:g} %"),
    ("principal_px", "principal pt [px]", lambda x: f"{x:g}"),
    ("hand_eye_deg", "hand-eye [deg]", lambda x: f"{x:g}"),
    ("hand_eye_tilt_deg", "its axis to optical axis [deg]", lambda x: f"{x:g}"),
    ("offset_cm", "offset [cm]", lambda x: f"{x:g}"),
    ("lag_frames", "lag [frames]", lambda x: f"{x:g}"),
    ("hover", "run 2 motion", lambda x: f"{x:g}"),
    ("jitter_deg", "jitter [deg]", lambda x: f"{x:g}"),
    ("jitter_cm", "jitter [cm]", lambda x: f"{x:g}"),
)
S1_NUMBERS = (
    ("run1", "pos_mean_cm", "run 1 pos mean [cm]"),
    ("run1", "pos_std_cm", "pos std"),
    ("run1", "rot_mean_deg", "rot mean [deg]"),
    ("run1", "rot_std_deg", "rot std"),
    ("run2_at_3m", "pos_mean_cm", "3 m pos mean"),
    ("run2_at_3m", "rot_mean_deg", "3 m rot mean"),
)


def _dev(x) -> str:
    return "inf" if x is None or not x < float("inf") else f"{x:.2f}"


def _reading(x: dict) -> str:
    return " | ".join(_cell(x, k, f) for k, _, f in S1_COLUMNS)


def _cell(x: dict, key: str, f) -> str:
    """A reading's value; "-" for a reading a result from before that column did not sweep."""
    return f(x[key]) if key in x else "-"


def s1_numbers(s: dict) -> str:
    return " | ".join(fmt(s[run].get(key), ".2f") for run, key, _ in S1_NUMBERS)


def seed001_section(r: dict) -> list:
    s1 = r["seed001"]
    rows, ch, paper = s1["rows"], s1["choice"], s1["paper"]
    best = ch["best"]
    lines = [
        "## Seed 001 experiment 1 (Sec. V-A): the seed's P3P pose against Vicon",
        "",
        "Seed baseline: P3P on three markers + the fourth-marker check, near-ties resolved by the "
        "regression prediction (Sec. IV), on the rendered frames of benchmarks.seed001 "
        f"({s1['frames']['run1']} frames at 0.68-1.74 m, {s1['frames']['run2']} up to 3 m), "
        "detected once. Left open by the text: the intrinsics the pose was computed with "
        "(focal and principal-point error), the Vicon body frame vs the camera (hand-eye "
        "rotation, its angle and the angle of its axis to the camera's optical axis) and the "
        "Vicon target frame vs the markers (offset), the camera-Vicon time "
        "offset (lag, in frame intervals of the simulated trajectory; run 2's motion at 3 m "
        "relative to the simulated one: the quadrotor hovers there), and the truth's per-frame "
        "jitter. The paper gives none of these. Offsets and jitter are averaged over random "
        "axes (the hand-eye axis: random azimuths about the optical axis). Scored: the six "
        "numbers "
        "below; the maxima (12.2 cm, 4.5 deg: single frames with three markers, Sec. V-A) are "
        "in the JSON, not scored.",
        "",
        "| "
        + " | ".join(h for _, h, _ in S1_COLUMNS)
        + " | "
        + " | ".join(h for _, _, h in S1_NUMBERS)
        + " | largest dev. |",
        "|" + "---|" * (len(S1_COLUMNS) + len(S1_NUMBERS) + 1),
        "| paper |"
        + " |" * (len(S1_COLUMNS) - 1)
        + " "
        + " | ".join(f"{paper[run][key]:g}" for run, key, _ in S1_NUMBERS)
        + " | |",
    ]
    stated = [x for x in rows if all(x.get(k, v) == v for k, v in STATED.items())]
    rest = sorted((x for x in rows if x not in stated), key=lambda x: x["max_deviation"])
    for x in stated + rest[:8]:
        lines.append(f"| {_reading(x)} | {s1_numbers(x)} | {_dev(x['max_deviation'])} |")
    ev = s1["evidence"]
    within, alone, others = ev["within_tol"], ev["alone"], ev["leave_one_out"]
    lines += [
        "",
        f"Rows: the stated reading (every error 0), then the best 8 of {s1['readings']} "
        f"(coarse grid, then {s1.get('refine_rounds', 2)} finer grids around the best so far) "
        "by largest deviation. "
        + (
            f"**A reading reproduces experiment 1** ({within} readings within 10 %)"
            if ch["reproduces"]
            else f"**No reading reproduces experiment 1 within 10 %** (best largest deviation "
            f"{best['max_deviation']:.3f})"
        )
        + ". Each number alone is met: best deviation "
        + ", ".join(f"{k} {v:.3f}" for k, v in alone.items())
        + ". Leaving one number out, the other five are met at best to "
        + ", ".join(f"{v:.3f} (without {k})" for k, v in others.items())
        + ". At the stated reading the seed's pose is "
        f"{fmt(stated[0]['run1']['pos_mean_cm'], '.2f')} cm / "
        f"{fmt(stated[0]['run1']['rot_mean_deg'], '.2f')} deg off in run 1: the rendered "
        "images alone cannot produce the paper's centimetre / degree errors, which need errors "
        "of the ground truth and the calibration that the paper does not report.",
        "",
        "Chosen: "
        + ", ".join(f"{h} {_cell(best, k, f)}" for k, h, f in S1_COLUMNS)
        + f" (largest deviation {best['max_deviation']:.3f}). "
        + s1_held_out(s1.get("held_out")),
        "",
        "| setting | method | frames localized (run 1 / at 3 m) | "
        + " | ".join(h for _, _, h in S1_NUMBERS)
        + " | run 1 pos max | rot max |",
        "|---|---|---|" + "---|" * (len(S1_NUMBERS) + 2),
    ]
    for name in ("stated", "reproducing"):
        for method in ("seed_baseline", "graphloc"):
            s = s1["runs"][name][method]
            lines.append(
                f"| {name} | {method.replace('_', ' ')} | {s['run1']['localized'][0]}/"
                f"{s['run1']['localized'][1]} / {s['run2_at_3m']['localized'][0]}/"
                f"{s['run2_at_3m']['localized'][1]} | {s1_numbers(s)} | "
                f"{fmt(s['run1'].get('pos_max_cm'), '.2f')} | "
                f"{fmt(s['run1'].get('rot_max_deg'), '.2f')} |"
            )
    lines += ["", s1_margin(s1), ""]
    if "why" in s1:
        lines += s1_why(s1["why"], best, paper["run1"])
    return lines


def s1_held_out(h: dict | None) -> str:
    """The chosen reading on draws and frames it was not chosen on."""
    if not h:
        return ""
    d = np.asarray(h["draws"])
    r = h["rendered"]
    return (
        f"Held out (it was chosen as the best of many draws): with {len(d)} other draws of "
        f"its random axes and jitter its largest deviation is median {np.median(d):.3f}, worst "
        f"{d.max():.3f} ({int((d <= REPRODUCE_TOL).sum())} of {len(d)} within 10 %); on frames "
        f"rendered anew (seed {r['seed']}) {r['max']:.3f}"
        + (
            f": its camera rolls {r['roll_rms_deg'][1]:.2f} deg rms per frame interval in run 1 "
            f"against {r['roll_rms_deg'][0]:.2f} in the swept frames; the lag's share of the "
            "error follows the simulated motion, which the paper does not give."
            if "roll_rms_deg" in r
            else "."
        )
    )


def s1_margin(s1: dict) -> str:
    parts = []
    for name in ("reproducing", "stated"):
        seed, ours = s1["runs"][name]["seed_baseline"], s1["runs"][name]["graphloc"]
        ratio = [
            ours[run][key] / seed[run][key]
            for run, key in (("run1", "pos_mean_cm"), ("run2_at_3m", "pos_mean_cm"))
        ]
        parts.append(
            f"at the {name} reading graphloc / seed position mean {ratio[0]:.2f} (run 1), "
            f"{ratio[1]:.2f} (at 3 m)"
        )
    return (
        "graphloc = the same detections written as a graphloc log (the reading's intrinsics) "
        "through the front door (open_run -> team graph -> batch LM; no odometry on this "
        "robot), scored against the same truth. Margin: " + "; ".join(parts) + ". Errors of "
        "the truth (hand-eye, offset, lag, jitter) hit both methods alike; graphloc places a "
        "frame only once its HypothesisTracker has committed (frames localized)."
    )


def seed003_section(r: dict) -> list:
    s3 = r["seed003"]
    rows, ch = s3["rows"], s3["choice"]
    best = ch["best"]
    ns = [str(n) for n in N_VALUES]
    lines = [
        "## Seed 003 Fig. 6 (Sec. III): the seed's EKF, T_x and T_z error vs N",
        "",
        "What the paper reports: Fig. 6's values are not in its text (the figure survives as "
        "axis ticks without a unit), so no Fig. 6 number can be met within 10 %. The text "
        'states (a) "for T_x, small N values give better estimation results", (b) "for Z, '
        "the estimation error tends to improve as N increases\", and the robot tracker's "
        'errors that feed the EKF (Fig. 3): "in the range of 2 cm, 0.8 cm and 9 cm" in X, Y, '
        "Z (read as the largest absolute error over the sequence). Left open: the tracker's "
        "error (our rendered front-end, or camera-frame centre errors with per-axis "
        f"std scale x (1, 0.4, 4.5) cm and disk tilt std scale x {TILT_DEG:g} deg), the EKF's "
        'tracker noise "set to 3" (px^2 or a 3 px std), the KLT points\' "high" initial std '
        '(1 m or 10 m) and the sequence ("12 frames", the tracked robot still; or the '
        f"crawler-pair benchmark's 16 frames). {s3['trials']} rendered sequences per schedule; "
        "(a) / (b): the least-squares slope of the T_x / T_z error against log N is positive "
        "/ negative (the text's trends; strict: every N = 1, 2 below every N = 10, 20 / T_z "
        "falling at every step, in parentheses); mean "
        "absolute error over the sequence and the trials [cm].",
        "",
        "| tracker (centre std X / Y / Z, tilt scale) | R tracker [px^2] | KLT init std [m] | "
        "sequence | tracker max X / Y / Z "
        "[cm] | EKF T_x N = "
        + " / ".join(ns)
        + " | EKF T_z N = "
        + " / ".join(ns)
        + " | (a) | (b) | Fig. 3 dev. |",
        "|---|---|---|---|---|---|---|---|---|---|",
        "| paper | | | | 2 / 0.8 / 9 | (a) | (b) | yes | yes | |",
    ]
    stated, rest = rows[:1], rows[1:]
    rest = sorted(
        rest,
        key=lambda x: (
            -(x["claim_tx_small_n_better"] + x["claim_tz_improves_with_n"]),
            x["max_deviation"],
        ),
    )
    for x in stated + rest[:9]:
        lines.append(_s3_row(x))
    both = ch["readings_with_both_claims"]
    lines += [
        "",
        f"Rows: the stated reading first, then the best 9 of {len(rows)} (both claims, then "
        "Fig. 3 deviation; the coarse grid, then the chosen reading's per-axis stds fitted to "
        "Fig. 3). "
        + (
            "**A reading reproduces what the paper states**"
            if ch["reproduces"]
            else "**No reading reproduces all of it**"
        )
        + f": {both} readings show (a) and (b), {ch['reproducing_readings']} of them with the "
        f"tracker within 10 % of Fig. 3 (strict readings: {ch.get('readings_with_both_strict')}"
        f", {ch.get('strict_within_tol')} of them within 10 % of Fig. 3). Chosen: tracker "
        f"{_tracker(best)}, "
        f"R {best['tracker_variance']:g} px^2, KLT init std {best['feature_sigma']:g} m, "
        f"{best['schedule']} (Fig. 3 deviation {_dev(best['max_deviation'])}). "
        + _s3_evidence(rows),
        "",
        "| setting | N | EKF T_x / T_y / T_z [cm] | graphloc T_x / T_y / T_z [cm] | "
        "graphloc / EKF (mean of axes) |",
        "|---|---|---|---|---|",
    ]
    for name in ("stated", "reproducing"):
        run = s3["runs"][name]
        for n in N_VALUES:
            e, g = (np.asarray(by_n(run[k], n)) for k in ("ekf_cm", "graphloc_cm"))
            lines.append(
                f"| {name} | {n} | {' / '.join(f'{v:.2f}' for v in e)} | "
                f"{' / '.join(f'{v:.2f}' for v in g)} | {g.mean() / e.mean():.2f} |"
            )
    lines.append("")
    return lines


def by_n(d: dict, n: int):
    return d[str(n)] if str(n) in d else d[n]


def _s3_evidence(rows: list) -> str:
    """Where (a) and (b) hold: the stated reading, and the readings showing both by tracker
    and by the KLT points' initial std."""
    st = rows[0]
    both = [x for x in rows if x["claim_tx_small_n_better"] and x["claim_tz_improves_with_n"]]
    rendered = sum(x["tracker_sd_cm"] is None for x in both)
    by_sigma = {f: sum(x["feature_sigma"] == f for x in both) for f in FEATURE_SIGMAS}
    return (
        "At the stated reading (rendered tracker) the tracker's largest errors are "
        + " / ".join(f"{v:.2f}" for v in st["tracker_max_cm"])
        + f" cm, (a) {_holds(st['claim_tx_small_n_better'])} and (b) "
        f"{_holds(st['claim_tz_improves_with_n'])}. Of the readings showing both, {rendered} "
        "use the rendered tracker; by the KLT points' initial std: "
        + ", ".join(f"{n} at {f:g} m" for f, n in by_sigma.items())
        + ". Fig. 6's values themselves are not in the text: only its two trends are checked."
    )


def _holds(flag) -> str:
    return "holds" if flag else "fails"


def yes_no(flag) -> str:
    return "yes" if flag else "no"


def _tracker(x: dict) -> str:
    """The reading's tracker: rendered, or its per-axis centre std and tilt scale."""
    if x["tracker_sd_cm"] is None:
        return "rendered"
    sd = " / ".join(f"{v:.2f}" for v in x["tracker_sd_cm"])
    return f"std {sd} cm, tilt x{x['tracker_scale']:g}"


def _s3_row(x: dict) -> str:
    tx = " / ".join(f"{by_n(x['ekf_cm'], n)[0]:.2f}" for n in N_VALUES)
    tz = " / ".join(f"{by_n(x['ekf_cm'], n)[2]:.2f}" for n in N_VALUES)
    tr = " / ".join(f"{v:.2f}" for v in x["tracker_max_cm"])
    return (
        f"| {_tracker(x)} | {x['tracker_variance']:g} | {x['feature_sigma']:g} | "
        f"{x['schedule']} | {tr} | {tx} | {tz} | "
        f"{yes_no(x['claim_tx_small_n_better'])} ({yes_no(x.get('strict_tx'))}) | "
        f"{yes_no(x['claim_tz_improves_with_n'])} ({yes_no(x.get('strict_tz'))}) | "
        f"{_dev(x['max_deviation'])} |"
    )


def sections(r: dict) -> list:
    """The seed 001 and seed 003 sections of a result that has them."""
    out = []
    if "seed001" in r:
        out += seed001_section(r)
    if "seed003" in r:
        out += seed003_section(r)
    return out


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
