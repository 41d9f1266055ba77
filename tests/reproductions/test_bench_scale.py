"""scripts/bench_scale.py end to end on a short synthetic MRCLAM run: the JSON, the markdown and
the PNG it writes, and the numbers it states against the targets of issue 15."""

import json

import pytest
from helpers import write_synthetic_mrclam

from benchmarks.bench_scale import main


@pytest.mark.slow
def test_bench_scale_writes_json_markdown_and_plot(tmp_path):
    write_synthetic_mrclam(tmp_path / "run", duration=20.0)
    doc = tmp_path / "results_scale.md"
    argv = [
        "--data",
        str(tmp_path / "run"),
        "--out",
        str(tmp_path / "out"),
        "--lags",
        "0,5",
        "--copies",
        "2",
        "--repeats",
        "2",
        "--relinearize",
        "0.05",
        "--marginalize-every",
        "1",
        "--markdown",
        str(doc),
    ]
    assert main(argv) == 0
    report = json.loads((tmp_path / "out" / "bench_scale.json").read_text())
    assert report == json.loads(doc.with_suffix(".json").read_text())
    b = report["batch"]
    assert b["graphloc_error"] <= b["gtsam_only"]["error"] * (1 + 1e-6)  # the warm start's gain
    assert abs(b["gtsam_only_from_warm_start"]["error"] - b["graphloc_error"]) < 1e-6 * max(
        1.0, b["graphloc_error"]
    )
    assert set(report["online"]) == {"0", "5"} | {f"{report['default_lag_s']:g}"}
    assert all(o["steps"] > 0 and o["ate_over_batch"] for o in report["online"].values())
    text = doc.read_text()
    assert "| ratio graphloc / GTSAM from the guess" in text and "results_scale.png" in text
    assert doc.with_suffix(".png").stat().st_size > 10_000
