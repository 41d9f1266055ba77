"""Markdown of the seeds' tables (docs/results.md, `graphloc reproduce`): one renderer per
table, paper | seed baseline (ours) | graphloc, from the plain dicts that
graphloc.experiments.seed000 (seed 000 Tables I-III) and graphloc.experiments.seed004
(seed 004 Table 1) return. Every number printed is one of the dict's."""

from __future__ import annotations


def _f(x, spec: str = ".2e") -> str:
    return "n/a" if x is None else format(x, spec)


def table_i(r: dict) -> str:
    """Seed 000 Table I (Sec. VI-A)."""
    p, s, g = r["paper"], r["seed_baseline"], r["graphloc"]
    gf, fl = r["graphloc_failures"], r["failures"]
    n, cfg = r["trials"], r["config"]
    lines = [
        f"### Seed 000 Table I: relative position error ({n} trials, error / {cfg['scale']:g} m)",
        "",
        "| quantity | paper | seed baseline (ours: P3P + straight-line test) "
        "| graphloc (joint GTSAM, shared rotation) |",
        "|---|---|---|---|",
        f"| success (closer to the truth than any pseudo solution) | "
        f"{p['success']}/{p['trials']} | {s['success']}/{n} | {g['success']}/{n} |",
        f"| all three positions within {cfg['success_tol']:g} m | -- | {s['within_tol']} | "
        f"{g['within_tol']} |",
    ]
    for cam in ("C2", "C3", "C"):
        lines.append(
            f"| {cam} mean (std), own successes | {p[cam][0]:.1e} ({p[cam][1]:.1e}) | "
            f"{_f(s[cam]['mean'])} ({_f(s[cam]['std'])}) | "
            f"{_f(g[cam]['mean'])} ({_f(g[cam]['std'])}) |"
        )
    sc, gc = s["common_trials"], g["common_trials"]
    for cam in ("C2", "C3", "C"):
        lines.append(
            f"| {cam} mean (std), the {r['common_successes']} trials both got right "
            f"| -- | {_f(sc[cam]['mean'])} ({_f(sc[cam]['std'])}) | "
            f"{_f(gc[cam]['mean'])} ({_f(gc[cam]['std'])}) |"
        )
    e = r["evidence"]
    median = e["genuine_p3p_error_true_ground_median_m"]
    p90 = e["genuine_p3p_error_true_ground_p90_m"]
    lines += [
        "",
        " ".join(
            [
                "C1 is the reference (error 0). Seed: C2, C3 from the three-robot algorithm",
                "(graphloc.vision.mutual) on the noisy omni pixels, then P3P + straight-line test",
                "(no",
                "threshold: the seed's 0.003 m would only reject more). graphloc: one GTSAM graph",
                "over",
                "all six cameras (mutual and climber bearings, known |T_12|, the climbing robot's",
                "rotation held over its straight move), started from the same front-end. Why the",
                "paper's accuracy is not reached: with the *true* ground positions the genuine P3P",
                f"candidate alone is already {median:.3f} m off (median; p90 {p90:.3f} m) at",
                "0.5 px on a",
                f"640 px / 120 deg camera, i.e. {median / cfg['scale']:.1e} relative -- the",
                "paper's",
                "5.7e-4 is below this noise floor. The seed's straight-line test is weak here:",
                "median",
                f"line error of the chosen combination {s['line_error_median_m']:.3f} m vs",
                f"{s['second_line_error_median_m']:.3f} m for the runner-up. graphloc's failures:",
                f"{gf['ground_triangle_rejected']} ground triangles rejected by",
                "graphloc.vision.mutual",
                "(e.g. noise pushed a pixel past the omni field of view),",
                f"{gf['consistent_fit_ill_conditioned']} fits as consistent as the successes'",
                "(graph",
                f"error <= their 99th percentile {gf['success_graph_error_p99']:.1f}:",
                "ill-conditioned,",
                "the P3P singularity the seed blames for its 3 failures),",
                f"{gf['poor_fit_wrong_basin']} poor fits,",
                f"{gf['optimizer_failed']} optimizer failures.",
                f"Simulation: {fl['camera_trials_redrawn']} camera placements and",
                f"{fl['formations_redrawn_not_mutually_visible']} ground formations",
                "(a robot outside",
                "another's 120 deg omni field of view) redrawn,",
                f"{fl['ground_orientation_redraws']} ground orientations redrawn.",
                "Readings of the seed's setup swept against the paper's numbers:",
                "docs/results_seed_baselines.md.",
            ]
        ),
    ]
    return "\n".join(lines) + "\n"


def table_ii(r: dict) -> str:
    """Seed 000 Table II (running times on this machine)."""
    d = r["deterministic_ms"]
    lines = [
        "### Seed 000 Table II: running time (this machine, median per trial / mean per update)",
        "",
        "| algorithm | paper | seed baseline (ours) | graphloc |",
        "|---|---|---|---|",
        "| deterministic (3 x P3P + straight-line test; graphloc + joint GTSAM) | "
        f"{r['paper_ms']['deterministic']} ms | {d['seed_baseline']:.2f} ms | "
        f"{d['graphloc']:.2f} ms |",
    ]
    if "deterministic_batched_ms" in r:
        b = r["deterministic_batched_ms"]
        lines.append(
            "| the same, all Table I trials batched (per trial; graphloc across workers) "
            f"| -- | {b['seed_baseline']:.3f} ms | {b['graphloc']:.2f} ms |"
        )
    if "update_ms" in r:
        u = r["update_ms"]
        lines.append(
            f"| one update (belief vector Def. 1 / HypothesisTracker) | "
            f"{r['paper_ms']['update']} ms | {u['belief_def1']:.3f} ms | "
            f"{u['tracker']:.3f} ms |"
        )
        lines += [
            "",
            f"Particle filter (seed 004) {u['particle_filter']:.3f} ms, belief Def. 2 "
            f"{u['belief_def2']:.3f} ms per update.",
        ]
    c = r["bearing_custom_factor_linearize"]
    lines += [
        "",
        "The paper's times are Matlab on a 2011 PC, including the simulation; ours "
        "exclude it. graphloc's joint graph uses the Python CustomFactor bearing_factor "
        f"(Pose3 -> Pose3, no built-in fits): {1e6 * c['custom_s']:.0f} us per "
        f"linearization vs {1e6 * c['builtin_s']:.0f} us for the built-in "
        f"BearingFactor3D ({c['ratio']:.1f}x).",
    ]
    return "\n".join(lines) + "\n"


def table_iii(r: dict) -> str:
    """Seed 000 Table III (Sec. VI-B)."""
    lines = [
        f"### Seed 000 Table III: mean updates to converge ({r['config']['runs']} runs per "
        "cell; wrong first locks / never converged)",
        "",
        "| cell | paper | seed baseline (ours): belief Def. 1 | belief Def. 2 | particle "
        "filter (seed 004) | graphloc HypothesisTracker | graphloc fewer than paper and "
        "belief |",
        "|---|---|---|---|---|---|---|",
    ]
    fewer = r["graphloc_fewer_updates_than_paper_and_belief"]
    for name, c in r["cells"].items():

        def cell(m):
            x = c[m]
            mean = _f(x["mean_updates_to_converge"], ".2f")
            return f"{mean} ({x['wrong_locks']}/{x['never_converged']})"

        lines.append(
            f"| {name} | {c['paper_table_iii']} | {cell('belief_def1')} | "
            f"{cell('belief_def2')} | {cell('particle_filter')} | {cell('tracker')} | "
            f"{'yes' if fewer[name] else 'no'} |"
        )
    lines += [
        "",
        "Mean updates to the first *correct* lock (runs never correctly locked):",
        "",
        "| cell | paper | belief Def. 1 | belief Def. 2 | particle filter | graphloc "
        "HypothesisTracker | graphloc fewer than paper and belief |",
        "|---|---|---|---|---|---|---|",
    ]
    fewer = r["graphloc_fewer_updates_to_correct_lock_than_paper_and_belief"]
    for name, c in r["cells"].items():

        def correct(m):
            x = c[m]
            return f"{_f(x['mean_updates_to_correct_lock'], '.2f')} ({x['never_correct']})"

        lines.append(
            f"| {name} | {c['paper_table_iii']} | {correct('belief_def1')} | "
            f"{correct('belief_def2')} | {correct('particle_filter')} | "
            f"{correct('tracker')} | {'yes' if fewer[name] else 'no'} |"
        )
    lines += [
        "",
        "Runs, engines and convergence rule: graphloc.experiments.hypotheses (update 1 = "
        "first odometry step). Wrong first locks count commits on a non-genuine "
        "candidate: a method that converges fast but wrongly is not better. Readings of the "
        "seed's setup (image noise, likelihood, odometry model) swept against the paper's "
        "numbers: docs/results_seed_baselines.md.",
    ]
    return "\n".join(lines) + "\n"


def seed004(r: dict) -> str:
    """Seed 004 Table 1 (Sec. III)."""
    lines = [
        f"### Seed 004 Table 1: P3P position error [m] ({r['runs']} tracks x {r['frames']} "
        "frames per cell)",
        "",
        "| focal | noise var [px^2] | paper mean (std) | seed baseline raw P3P: RMS / mean "
        "(std) | graphloc smoothed: RMS / mean (std) |",
        "|---|---|---|---|---|",
    ]
    for c in r["cells"]:
        p, s, g = c["paper"], c["seed_baseline_raw_p3p"], c["graphloc_smoothed"]
        lines.append(
            f"| {c['focal_mm']:g} mm | {c['noise_variance']:g} | {p['mean']:.4f} "
            f"({p['std']:.4f}) | {s['rms']:.4f} / {s['mean']:.4f} ({s['std']:.4f}) | "
            f"{g['rms']:.4f} / {g['mean']:.4f} ({g['std']:.4f}) |"
        )
    st, first = r["setup"], r["cells"][0]
    lines += [
        "",
        f"Setup where the seed is silent: camera {st['height']} m above the LEDs, pixel "
        f"pitch {st['pixel_pitch_um']} um ({st['width']}x{st['height_px']}), track step "
        f"{st['step']} m, odometry {100 * st['odometry_noise']:.0f} % / "
        f"{st['odometry_rot_sigma']} rad. The absolute errors depend on these (not "
        "given in the seed), so the paper's numbers are not matched; both columns use "
        "the genuine P3P candidate of the same frames. A narrow lens looking down on a "
        "0.3 m triangle from this range sees it nearly fronto-parallel, where its tilt "
        "is observable only at second order (cos t ~ 1 - t^2/2), so the tilt -- and "
        "with it the camera's lateral position -- is ill-conditioned; the raw error "
        "stays large away from the danger cylinder too "
        f"({first['raw_p3p_rms_far_from_danger_cylinder']:.3f} m RMS vs "
        f"{first['raw_p3p_rms_near_danger_cylinder']:.3f} m near it in the first cell). "
        "Graph-smoothed RMS below raw P3P in all nine cells: "
        f"{'yes' if r['target_smoothed_below_raw_in_all_cells'] else 'NO'}. The readings "
        "of the setup under which the seed's own P3P error meets the paper's, and both "
        "columns there: docs/results_seed_baselines.md.",
    ]
    return "\n".join(lines) + "\n"


# ---- issue 20: readings of the seeds' setups (graphloc.experiments.seed_baselines) ----------
def _dev(x: float) -> str:
    return "inf" if x is None or not x < float("inf") else f"{x:.2f}"


def _top(rows: list, stated, n: int = 8) -> list:
    """The stated reading's row first, then the n best others by largest deviation."""
    first = [r for r in rows if stated(r)]
    rest = sorted((r for r in rows if not stated(r)), key=lambda r: r["max_deviation"])
    return first + rest[:n]


def _pair(x) -> str:
    return "n/a" if x is None else f"{x[0]:.1e} ({x[1]:.1e})"


def _sb_table1(r: dict) -> list:
    sw, runs = r["sweeps"]["table1"], r["runs"]
    ch = sw["choice"]
    best, p = ch["best"], sw["paper"]
    lines = [
        "## Seed 000 Table I (Sec. VI-A): P3P + straight-line test",
        "",
        'Left open by the text: the image noise "N(0, 0.5) pixels at a random direction" '
        "(std, variance, or a radius in another unit: swept as an effective std), the "
        'climbing robot\'s "N(0, 0.001) meter" perpendicular noise (std, variance, smaller), '
        "whether C keeps its orientation over the three snapshots, and which combination is "
        'the "second best" (any other, or Fig. 4\'s: only the 2nd snapshot pseudo; the closer '
        "one is scored). Correct = genuine combination picked and every position within "
        '0.003 m ("a relative error of 1e-3 ... out of a scale of three meters").',
        "",
        "| image std [px] | lateral [m] | orientation | correct /1000 | C2 | C3 | C | "
        "genuine line mean / max [m] | runner-up mean (any / 2nd pseudo) [m] | largest dev. |",
        "|---|---|---|---|---|---|---|---|---|---|",
        f"| paper | | | {p['success']} | {_pair(p['C2'])} | {_pair(p['C3'])} | "
        f"{_pair(p['C'])} | 3.19e-04 / 8.53e-03 | 0.771 | |",
    ]
    for x in _top(
        sw["rows"],
        lambda x: (x["pixel_sigma"], x["lateral_sigma"], x["orientation"]) == (0.5, 0.001, "kept"),
    ):
        lines.append(
            f"| {x['pixel_sigma']:g} | {x['lateral_sigma']:g} | {x['orientation']} | "
            f"{1000 * x['correct'] / x['trials']:.0f} | {_pair(x['C2'])} | {_pair(x['C3'])} | "
            f"{_pair(x['C'])} | {_f(x['line_genuine_mean_m'])} / "
            f"{_f(x['line_genuine_max_m'])} | {_f(x['line_second_mean_m'], '.3f')} / "
            f"{_f(x['line_second_pseudo_middle_mean_m'], '.3f')} | "
            f"{_dev(x['max_deviation'])} |"
        )
    # evidence: where each number alone is matched best (same lateral / orientation as best)
    same = [
        x
        for x in sw["rows"]
        if x["lateral_sigma"] == best["lateral_sigma"] and x["orientation"] == best["orientation"]
    ]

    def argbest(key):
        x = min(same, key=lambda x: x["deviation"][key])
        return f"{x['pixel_sigma']:g} px (dev. {_dev(x['deviation'][key])})"

    lines += [
        "",
        f"Rows: the stated reading, then the best {len(lines) - 10} of {len(sw['rows'])} by "
        "largest deviation (all in the JSON and the plot). "
        + (
            "**A reading reproduces Table I**"
            if ch["reproduces"]
            else f"**No reading reproduces Table I** (best largest deviation "
            f"{_dev(best['max_deviation'])})"
        )
        + f". Each number alone, at lateral {best['lateral_sigma']:g} m / "
        f"{best['orientation']}: correct results best at {argbest('correct')}, C2 mean at "
        f"{argbest('C2_mean')}, C mean at {argbest('C_mean')}, the genuine line error at "
        f"{argbest('line_genuine_mean')}, the runner-up at {argbest('line_second_mean')}. "
        "The errors scale with the image noise while 997/1000 correct needs nearly all "
        "trials under 3 mm, so the paper's accuracy and its success count call for different "
        "noise levels, and the runner-up's 0.771 m is not reached at any noise: in this "
        "geometry the pseudo solutions also move nearly straight.",
        "",
        f"Chosen (smallest largest deviation): image std {best['pixel_sigma']:g} px, "
        f"lateral {best['lateral_sigma']:g} m, orientation {best['orientation']}.",
        "",
        "| setting | seed correct (genuine picked) | graphloc correct | C2 seed / graphloc | "
        "C seed / graphloc |",
        "|---|---|---|---|---|",
    ]
    for name in ("stated", "reproducing"):
        t = runs[name]["table1"]
        s, g = t["seed_baseline"], t["graphloc"]
        lines.append(
            f"| {name} ({t['config']['pixel_sigma']:g} px) | {s['success']}/{t['trials']} | "
            f"{g['success']}/{t['trials']} | {_f(s['C2']['mean'])} / {_f(g['C2']['mean'])} | "
            f"{_f(s['C']['mean'])} / {_f(g['C']['mean'])} |"
        )
    lines += [
        "",
        "(correct here: closer to the truth than any pseudo solution in all three snapshots, "
        "graphloc.experiments.seed000; C errors relative, over each method's own successes.)",
        "",
    ]
    return lines


def _sb_table3(r: dict) -> list:
    sw, runs = r["sweeps"]["table3"], r["runs"]
    ch = sw["choice"]
    best = ch["best"]
    names = list(best["cells"])
    lines = [
        "## Seed 000 Table III (Sec. VI-B): belief vector, mean updates to converge",
        "",
        "Left open by the text: the image noise (as above), the likelihood -- Def. 1's "
        "normalized inner product floored at 1e-3 or shifted to (1 + cos) / 2, Def. 2's "
        'distance (13) as exp(-d) or 1 / (1 + d) -- and the odometry noise "15% on all three '
        'dimensions" (per axis, or isotropic at 15 % of the step), and the frame of the action '
        "a_t (rotated into the world by each solution's rotation, or one world-frame motion "
        "reading for all solutions). Cells: mean updates to "
        "converge (wrong first locks); last columns: largest deviation, wrong locks and runs "
        "whose committed belief fell to the threshold again (the paper: never), over all "
        f"cells, {best['cells'][names[0]]['runs']} runs per cell.",
        "",
        "| image std [px] | odometry | likelihood | action frame | "
        + " | ".join(names)
        + " | largest dev. | wrong | relocalized |",
        "|---|---|---|---|" + "---|" * len(names) + "---|---|---|",
        "| paper | | | | "
        + " | ".join(f"{best['cells'][n]['paper']:g}" for n in names)
        + " | | | 0 |",
    ]
    for x in _top(
        sw["rows"],
        lambda x: (
            (x["pixel_sigma"], x["odometry_model"], x["likelihood"], x.get("action_frame"))
            == (0.5, "per_axis", "inner_product", "solution")
        ),
    ):
        cells = " | ".join(
            f"{_f(x['cells'][n]['mean_updates_to_converge'], '.2f')} "
            f"({x['cells'][n]['wrong_locks']})"
            for n in names
        )
        lines.append(
            f"| {x['pixel_sigma']:g} | {x['odometry_model']} | {x['likelihood']} | "
            f"{x.get('action_frame', 'solution')} | {cells} | "
            f"{_dev(x['max_deviation'])} | {x['wrong_locks']} | "
            f"{x['runs_with_relocalization']} |"
        )
    lines += [
        "",
        (
            "**A reading reproduces Table III**"
            if ch["reproduces"]
            else "**No reading reproduces Table III within 10 %**"
        )
        + f" ({ch['reproducing_readings']} of {len(sw['rows'])} readings do). Chosen: image "
        f"std {best['pixel_sigma']:g} px, odometry {best['odometry_model']}, likelihood "
        f"{best['likelihood']}, action frame {best.get('action_frame', 'solution')} (largest "
        f"deviation {_dev(best['max_deviation'])}).",
        "",
        _t3_evidence(sw["rows"]),
        "",
        "graphloc at the stated setting and at the chosen reading (graphloc.experiments."
        "seed000.table_iii, same runs for every method; belief = the chosen likelihood's "
        "definition): mean updates to the first commit (wrong first locks) / to the first "
        "correct commit (runs never correct).",
        "",
        "| setting | cell | paper | belief Def. 1 | belief Def. 2 | graphloc tracker |",
        "|---|---|---|---|---|---|",
    ]
    for name in ("stated", "reproducing"):
        t = runs[name]["table3"]
        for cell, c in t["cells"].items():

            def m(key):
                x = c[key]
                return (
                    f"{_f(x['mean_updates_to_converge'], '.2f')} ({x['wrong_locks']}) / "
                    f"{_f(x['mean_updates_to_correct_lock'], '.2f')} ({x['never_correct']})"
                )

            lines.append(
                f"| {name} | {cell} | {c['paper_table_iii']} | {m('belief_def1')} | "
                f"{m('belief_def2')} | {m('tracker')} |"
            )
    lines.append("")
    return lines


def _t3_evidence(rows: list) -> str:
    """Why no Table III reading fits: the readings free of wrong locks and their deviation,
    the cells within 10 %, and the runs that fall under the threshold again."""
    clean = [x for x in rows if x["wrong_locks"] == 0]
    runs = sum(c["runs"] for c in rows[0]["cells"].values())
    within = max(sum(c["deviation"] <= 0.1 for c in x["cells"].values()) for x in rows)
    reloc = min(x["runs_with_relocalization"] for x in rows)
    text = (
        f"Evidence: {len(clean)} of {len(rows)} readings never lock wrongly (the paper's "
        "converged runs stay on the genuine track)"
    )
    if clean:
        b = min(clean, key=lambda x: x["max_deviation"])
        text += (
            f"; the best of them ({b['pixel_sigma']:g} px, {b['odometry_model']}, "
            f"{b['likelihood']}) still deviates by {_dev(b['max_deviation'])}"
        )
    return (
        text + f". At most {within} of the 6 cells fall within 10 % under any one reading. "
        f"Every reading has runs whose committed belief falls to the threshold again (at "
        f"least {reloc} of {runs}): a traced solution is lost when P3P solutions merge or "
        "jump past the 0.05 m gate, which the paper says never happens."
    )


def _sb_seed004(r: dict) -> list:
    sw, runs = r["sweeps"]["seed004"], r["runs"]
    ch = sw["choice"]
    best = ch["best"]
    infeasible = sum(x["infeasible"] is not None for x in sw["rows"])
    lines = [
        "## Seed 004 Table 1 (Sec. III): raw P3P position error",
        "",
        "Left open by the text: the camera's height over the LEDs, the pixel pitch (a 2/3\" "
        "sensor kept, so the resolution follows), where the camera is relative to the LED "
        'triangle (horizontal offset: 0 = overhead), and "Gaussian noise with sigma^2 = v" '
        "read as a variance or as a standard deviation. The LED triangle (0.3048 m "
        f"equilateral) is stated. {infeasible} of {len(sw['rows'])} readings lose an LED "
        "from the image (infeasible). Largest deviation over the 9 means and 9 stds:",
        "",
        "| height [m] | pitch [um] | offset [m] | sigma^2 read as | largest dev. |",
        "|---|---|---|---|---|",
    ]
    for x in _top(
        sw["rows"],
        lambda x: (
            (x["height"], x["pitch_um"], x["offset"], x["noise_reading"])
            == (2.5, 13.75, 0.0, "variance")
        ),
    ):
        lines.append(
            f"| {x['height']:g} | {x['pitch_um']:g} | {x['offset']:g} | {x['noise_reading']} | "
            f"{_dev(x['max_deviation'])} |"
        )
    std_rows = [x for x in sw["rows"] if x["noise_reading"] == "std" and x["cells"]]
    best_std = min((x["max_deviation"] for x in std_rows), default=None)
    lines += [
        "",
        (
            "**A reading reproduces Table 1**"
            if ch["reproduces"]
            else "**No reading reproduces Table 1 within 10 %**"
        )
        + f" ({ch['reproducing_readings']} readings do). Chosen: height {best['height']:g} m, "
        f"pitch {best['pitch_um']:g} um, offset {best['offset']:g} m, sigma^2 read as "
        f"{best['noise_reading']} (largest deviation {_dev(best['max_deviation'])}). Read as "
        f"a standard deviation the best reading deviates by {_dev(best_std)}: the paper's "
        "errors grow like sqrt(v), not v. Overhead (offset 0) the triangle is seen nearly "
        "fronto-parallel, its tilt only at second order, and the error no longer scales like "
        "1 / focal as the paper's does.",
        "",
        "| setting | focal | v [px^2] | paper mean (std) | seed raw P3P mean (std) | "
        "graphloc smoothed mean (std) | graphloc / seed |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in ("stated", "reproducing"):
        for c in runs[name]["seed004"]["cells"]:
            p, s, g = c["paper"], c["seed_baseline_raw_p3p"], c["graphloc_smoothed"]
            lines.append(
                f"| {name} | {c['focal_mm']:g} mm | {c['noise_variance']:g} | {p['mean']:.4f} "
                f"({p['std']:.4f}) | {s['mean']:.4f} ({s['std']:.4f}) | {g['mean']:.4f} "
                f"({g['std']:.4f}) | {g['mean'] / s['mean']:.2f} |"
            )
    lines.append("")
    return lines


def seed_baselines(r: dict, png: str) -> str:
    """docs/results_seed_baselines.md (issue 20) from graphloc.experiments.seed_baselines_report."""
    sizes = r["sweeps"]
    head = [
        "# The seeds' own methods under readings of the seeds' setups",
        "",
        f"Generated by `scripts/bench_seed_baselines.py{' --quick' if r['quick'] else ''}` "
        f"in {r['wall_time_s']:.0f} s (workers={r['workers']}; sweeps "
        f"{sizes['sweep_wall_time_s']:.0f} s). Every number below is computed by that run; "
        f"JSON `out/seed_baselines/seed_baselines.json`, plot `{png}`. For each seed table: "
        "what the seed's text leaves open, OUR implementation of the SEED's method under each "
        "reading against the SEED's own numbers (deviation = |ours / paper - 1|; reproduced = "
        "every number within 10 %), the chosen reading (smallest largest deviation), and "
        "graphloc re-run at the stated setting and at the chosen one.",
        "",
        f"![sweeps]({png})",
        "",
    ]
    return "\n".join(head + _sb_table1(r) + _sb_table3(r) + _sb_seed004(r))
