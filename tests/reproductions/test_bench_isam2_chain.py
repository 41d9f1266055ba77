"""scripts/bench_isam2_chain.py end to end on a short chain: every ISAM2Params variant under
this interpreter, the JSON, the doc (benchmarks.render.isam2_chain) and the PNGs it writes."""

import importlib.util
import json
import sys
from pathlib import Path

import pytest

from benchmarks.render import render

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "bench_isam2_chain.py"


@pytest.mark.slow
def test_bench_isam2_chain_writes_json_doc_and_plots(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(SCRIPT.parent))  # the script imports isam2_chain_repro
    spec = importlib.util.spec_from_file_location("bench_isam2_chain", SCRIPT)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    doc = tmp_path / "gtsam_isam2_chain.md"
    argv = ["--python", sys.executable, "--poses", "400", "--out", str(tmp_path / "out")]
    assert bench.main(argv + ["--markdown", str(doc)]) == 0
    report = json.loads((tmp_path / "out" / "bench_isam2_chain.json").read_text())
    assert report == json.loads(doc.with_suffix(".json").read_text())
    # every variant once with a prior on every pose, the defaults once more with one prior
    variants = [r["variant"] for r in report["runs"]]
    assert variants == list(bench.repro.VARIANTS) + ["defaults"]
    assert [r["prior_every_pose"] for r in report["runs"]].count(False) == 1
    assert all(r["poses"] == 400 and r["total_s"] > 0 for r in report["runs"])
    assert "def chain(" in report["reproduction"]
    text = doc.read_text()
    assert text == render("isam2_chain", report, doc="gtsam_isam2_chain")
    assert "```python\ndef chain(" in text and "| gtsam" in text
    assert doc.with_suffix(".png").stat().st_size > 10_000
    assert (tmp_path / "out" / "isam2_chain_update_cpu.png").is_file()
