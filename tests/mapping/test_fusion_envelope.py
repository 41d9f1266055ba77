"""`scripts/bench_fusion.py --real --envelope` (benchmarks.fusion_envelope): the real
benchmark's trials under other view noise and densities, summarized per condition and cell."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.fusion_bench import main as bench_main
from benchmarks.fusion_envelope import main_envelope, summarize_envelope
from benchmarks.fusion_report_real import REAL_METHODS
from benchmarks.real_views import BUNDLED_FRAGMENTS
from benchmarks.render import render


def _row(fragment, noise, keep, overlap, seed, hint, graphloc):
    """A `run_real_trial` row as the summary reads it: every method right and accepted but
    graphloc, whose (rot_deg, trans_m, accepted) is given."""
    ok = {"rot_deg": 0.05, "trans_m": 0.002, "seconds": 0.2, "accepted": True}
    row = {m: dict(ok) for m in REAL_METHODS}
    rot, tr, acc = graphloc
    row["graphloc"] = dict(ok, rot_deg=rot, trans_m=tr, accepted=acc, nees=6.0)
    row.update(
        fragment=fragment,
        noise_m=noise,
        keep=keep,
        overlap_target=overlap,
        overlap=overlap,
        seed=seed,
        hint_rot_deg=hint[0],
        hint_trans_m=hint[1],
        graphloc_own_prepare_s=0.1,
        last_stage_from_truth={
            "rot_deg": 0.05,
            "trans_m": 0.002,
            "bound_rot_cov_deg2": (1e-4 * np.eye(3)).tolist(),
        },
    )
    return row


def test_the_envelope_counts_each_conditions_false_accepts_and_refusals():
    rows = []
    for noise, outcome in ((0.005, (0.05, 0.002, True)), (0.01, (2.0, 0.08, True))):
        for seed in range(3):
            for hint in ((3.0, 0.05), (10.0, 0.2)):
                last = outcome if seed == 0 else (0.05, 0.002, seed == 1)  # one refusal per cell
                rows.append(_row("room.ply", noise, 0.5, 0.3, seed, hint, last))
    entries = summarize_envelope(rows)
    assert [(e["fragment"], e["noise_m"], e["keep"]) for e in entries] == [
        ("room.ply", 0.005, 0.5),
        ("room.ply", 0.01, 0.5),
    ]
    for e, fa in zip(entries, (0, 1)):
        assert len(e["cells"]) == 2
        for c in e["cells"].values():
            assert c["trials"] == 3 and c["not_fused"] == 1 and c["fpfh_successes"] == 3
            assert (c["successes"], c["false_accepts"]) == (2 - fa, fa)
    report = {
        "command": "python scripts/bench_fusion.py --real --envelope --trials 3 --seed 2000",
        "trials_per_overlap": 3,
        "wall_time_s": 1.0,
        "workers": 1,
        "png": "x.png",
        "entries": entries,
    }
    text = render("fusion_envelope", report)
    protocol, noisy = (ln for ln in text.splitlines() if ln.startswith("| room.ply"))
    assert "(protocol)" in protocol and "**[" not in protocol and "{1}" in protocol
    assert noisy.count("**[1]**") == 2 and "(protocol)" not in noisy
    assert "False accepts over every condition: 2 of 12 registrations." in text


def test_the_envelope_refuses_options_it_would_ignore():
    with pytest.raises(SystemExit, match="two runs"):
        bench_main(["--real", "--envelope", "--calibrate"])
    with pytest.raises(SystemExit, match="noise and kept fraction itself"):
        bench_main(["--real", "--envelope", "--noise", "0.01"])


@pytest.mark.slow
def test_the_envelope_runs_the_benchmark_trials_under_each_view_condition(tmp_path):
    fragment = str(BUNDLED_FRAGMENTS[1])  # the Redwood living room
    args = SimpleNamespace(
        fragment=fragment,
        trials=1,
        seed=2000,
        workers=1,
        out=str(tmp_path),
        doc=str(tmp_path / "e.md"),
    )
    assert main_envelope(args, views=((0.005, 0.5), (0.01, 0.25))) == 0
    report = json.loads((tmp_path / "bench_fusion_envelope.json").read_text())
    assert [(e["fragment"], e["noise_m"], e["keep"]) for e in report["entries"]] == [
        ("redwood_livingroom.ply", 0.005, 0.5),
        ("redwood_livingroom.ply", 0.01, 0.25),
    ]
    assert {r["noise_m"] for r in report["trials"]} == {0.005, 0.01}
    for e in report["entries"]:
        assert len(e["cells"]) == 4  # two overlaps, two hints
        for c in e["cells"].values():
            assert c["trials"] == 1
            assert c["successes"] + c["false_accepts"] + c["not_fused"] == 1
    assert (tmp_path / "e.png").stat().st_size > 0
    assert (
        f"--envelope --trials 1 --seed 2000 --fragment {fragment}"
        in (tmp_path / "e.md").read_text()
    )
