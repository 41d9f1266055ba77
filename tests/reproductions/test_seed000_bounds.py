"""Issue 20: the seed 000 bounds (benchmarks.seed_baselines_bounds) on small
instances: brackets of a monotone family, the noise-free trace of the genuine P3P solution,
Table I's intervals and Table III's per-reading intervals."""

import itertools

import numpy as np
import pytest

from benchmarks.baselines.belief_vector import BeliefVectorConfig
from benchmarks import seed_baselines as sb
from benchmarks import seed_baselines_bounds as bounds
from benchmarks import seed_baselines_bounds_t3 as bounds3
from benchmarks.hypotheses import CELLS, PAPER_TABLE_III

SIGMAS = (0.001, 0.01, 0.1, 1.0)


def test_interval_brackets_the_hits_and_widens_over_a_jumped_band():
    iv = bounds.interval(SIGMAS, [True, True, False, False], [0, 0, -1, -1])
    assert (iv["lo"], iv["hi"], iv["outer_lo"], iv["outer_hi"]) == (0.001, 0.01, 0.0, 0.1)
    assert iv["contiguous"] and iv["jumps"] == []
    # below the band at 0.01, above at 0.1: the band may lie between them
    iv = bounds.interval(SIGMAS, [False] * 4, [-1, -1, 1, 1])
    assert iv["lo"] is None and (iv["outer_lo"], iv["outer_hi"]) == (0.01, 0.1)
    assert not iv["contiguous"]
    assert bounds.interval(SIGMAS, [False] * 4, [-1] * 4) is None


def test_disjoint_pair_names_the_numbers_whose_brackets_do_not_meet():
    low = bounds.interval(SIGMAS, [True, False, False, False])
    high = bounds.interval(SIGMAS, [False, False, True, True])
    d = bounds.disjoint_pair({"a": low, "b": high})
    assert (d["ends_first"], d["below"], d["starts_last"], d["above"]) == ("a", 0.01, "b", 0.01)
    overlap = bounds.interval(SIGMAS, [False, True, True, False])
    assert bounds.disjoint_pair({"a": overlap, "b": high}) is None
    assert bounds.disjoint_pair({"a": low, "b": None}) == {"empty": ["b"]}


def test_side_against_the_paper_band():
    assert bounds.side((1.0, 0.95, 1.05), 1.0) == 0
    assert bounds.side((0.5, 0.4, 0.85), 1.0) == -1
    assert bounds.side((2.0, 1.2, 3.0), 1.0) == 1
    assert bounds.side((0.5, 0.4, 0.95), 1.0) == 0  # the interval reaches the band
    assert bounds.side(None, 1.0) is None


def test_noise_free_trace_keeps_the_genuine_solution_and_a_tight_gate_loses_it():
    ev = bounds3.tracing_events("level", "line", seed=0)
    assert ev["genuine_error_max_m"] < 1e-9  # noise-free P3P: the genuine solution is exact
    assert ev["lost"] == [] and ev["frames"] > 10
    tight = bounds3.tracing_events(
        "level", "line", 0, config=BeliefVectorConfig(gate_distance=1e-3)
    )
    assert len(tight["lost"]) == ev["frames"] - 1  # every step (>= 2 cm) leaves a 1 mm gate
    # the noise-free trajectory does not depend on the run's seed
    assert bounds3.tracing_events("level", "line", 5)["trajectory_digest"] == pytest.approx(
        ev["trajectory_digest"]
    )


def test_image_noise_loses_the_genuine_trace_the_noise_free_one_keeps():
    r = bounds3.table3_traces(1, sigmas=(0.0, 0.005), progress=False)
    noise_free, noisy = r["by_sigma"]
    assert noise_free["runs_lost"] == 0
    level_line = noisy["cells"]["level/line"]
    assert level_line["runs_lost"] == 1 and level_line["bound_exceeds_paper"]
    assert level_line["updates_bound"] > level_line["paper"]
    assert r["noise_free"]["level/line"]["identical_trajectories"]


def test_table1_intervals_separate_the_correct_count_from_the_c_mean():
    r = bounds.table1_intervals(
        150, 1, sigmas=(1e-4, 1e-3, 0.005, 0.1, 0.3), readings=[(0.0, "kept")], progress=False
    )
    (x,) = r["readings"]
    correct = x["intervals"]["correct"]
    assert correct["lo"] == 1e-4 and correct["outer_hi"] <= 0.005
    assert x["monotone"]["correct"] == "decreasing"
    d = x["disjoint_correct_vs_C_mean"]
    assert d["ends_first"] == "correct" and d["starts_last"] == "C_mean"
    assert d["above"] >= d["below"]
    value, lo, hi = x["series"]["correct"][0]
    assert lo <= value <= hi


def _row(sigma, m, lik, frame, mean, reloc):
    cells = {
        f"{c}/{v}": {
            "mean_updates_to_converge": mean * p,
            "std_updates_to_converge": 0.01,
            "converged_runs": 12,
            "paper": p,
        }
        for (c, v), p in PAPER_TABLE_III.items()
    }
    return {
        "pixel_sigma": sigma,
        "odometry_model": m,
        "likelihood": lik,
        "action_frame": frame,
        "cells": cells,
        "runs_with_relocalization": reloc,
        "wrong_locks": 0,
    }


def test_table3_intervals_prove_updates_and_no_relocalization_exclusive():
    # every cell converges as the paper only at 0.1 px; runs relocalize from 0.05 px on
    sigmas = (0.0, 0.01, 0.05, 0.1)
    mean = {0.0: 3.0, 0.01: 2.0, 0.05: 1.5, 0.1: 1.0}
    reloc = {0.0: 0, 0.01: 0, 0.05: 2, 0.1: 5}
    rows = [
        _row(s, m, lik, fr, mean[s], reloc[s])
        for s, (m, lik, fr) in itertools.product(
            sigmas, itertools.product(sb.T3_ODOMETRY, sb.T3_LIKELIHOODS, sb.T3_ACTION_FRAMES)
        )
    ]
    out = bounds3.table3_intervals(rows, sigmas)
    assert len(out) == len(sb.T3_ODOMETRY) * len(sb.T3_LIKELIHOODS) * len(sb.T3_ACTION_FRAMES)
    x = out[0]
    assert x["intervals"]["no_relocalization"]["outer_hi"] == 0.05
    cell = "/".join(CELLS[0])
    assert x["intervals"][cell]["outer_lo"] == 0.05
    assert x["disjoint"]["ends_first"] == "no_relocalization"
    assert x["monotone"][cell] == "decreasing"
    assert np.isclose(x["disjoint"]["ratio"], 1.0)


def test_bounds_sections_and_plots_render_from_their_dicts(tmp_path):
    from benchmarks import seed_baselines_bounds_report as report
    from benchmarks.render.seed_baselines_bounds import table1_bounds, table3_bounds

    sigmas = (0.0, 0.005)
    readings = list(itertools.product(sb.T3_ODOMETRY, sb.T3_LIKELIHOODS, sb.T3_ACTION_FRAMES))
    rows = [
        _row(s, m, lik, fr, {0.0: 1.0, 0.005: 0.5}[s], {0.0: 0, 0.005: 3}[s])
        for s, (m, lik, fr) in itertools.product(sigmas, readings)
    ]
    b = {
        "table1": bounds.table1_intervals(
            100, 1, sigmas=(1e-3, 0.01, 0.05, 0.3), readings=[(0.0, "kept")], progress=False
        ),
        "table3": {
            "sigmas": list(sigmas),
            "runs_per_cell": 1,
            "confidence": bounds.CONFIDENCE,
            "traces": bounds3.table3_traces(1, sigmas=sigmas, progress=False),
            "rows": rows,
            "readings": bounds3.table3_intervals(rows, sigmas),
            "wall_time_s": 0.0,
        },
    }
    t1, t3 = table1_bounds(b["table1"]), table3_bounds(b["table3"])
    row = t1["brackets"].iloc[0]
    assert (row["lateral [m]"], row["orientation"]) == ("0", "kept")
    assert row["proof"].startswith("correct /1000 needs <")
    # the synthetic means meet the paper at 0 px only, where no run relocalizes
    assert min(t3["all_cells"]) == 0.005 and "0.005" in list(t3["traces"]["image std [px]"])
    report.plot(b, tmp_path)
    assert (tmp_path / report.T1_PNG).stat().st_size > 0
    assert (tmp_path / report.T3_PNG).stat().st_size > 0
