"""scripts/bench_seed003.py end to end on one short trial: the JSON, the doc rendered from it
(benchmarks.render.seed003) with that JSON beside it, and the plots."""

import json

import pytest

from benchmarks.render import render
from benchmarks.seed003 import main
from benchmarks.seed003_measures import METHODS


@pytest.mark.slow
def test_bench_seed003_writes_json_doc_and_plots(tmp_path):
    doc = tmp_path / "results_seed003.md"
    argv = ["--trials", "1", "--n-features", "10", "--out", str(tmp_path / "out")]
    assert main(argv + ["--doc", str(doc)]) == 0
    report = json.loads((tmp_path / "out" / "bench_seed003.json").read_text())
    assert report == json.loads(doc.with_suffix(".json").read_text())
    assert report["command"] == "scripts/bench_seed003.py " + " ".join(argv + ["--doc", str(doc)])
    assert report["seeds"] == [0] and report["n_values"] == [10]
    assert set(METHODS) <= set(report["per_n"]["10"])
    text = doc.read_text()
    assert text == render("seed003", report, doc="results_seed003")
    rows = [x for x in text.splitlines() if x.startswith("| 10 ")]
    assert len(rows) == len(METHODS) + 1  # a row per method, and the max-mixture's row
    assert text.count("- PASS: ") + text.count("- FAIL: ") == len(report["checks"]) > 0
    for png in ("axis_errors.png", "error_curves.png", "scale_error.png"):
        assert (tmp_path / "out" / png).stat().st_size > 10_000
