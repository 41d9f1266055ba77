"""scripts/bench_executor.py's report: the doc rendered from its JSON (benchmarks.render.executor)
through write_report, with the JSON beside it -- from docs/results_executor.json (--doc-only) and
(slow, needs Ray) end to end on two short runs."""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.render import DOCS_DIR, render

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "bench_executor.py"


def _script():
    spec = importlib.util.spec_from_file_location("bench_executor", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_doc_only_writes_the_committed_doc_from_its_json(tmp_path):
    out, doc = tmp_path / "out", tmp_path / "results_executor.md"
    out.mkdir()
    shutil.copy(DOCS_DIR / "results_executor.json", out / "bench_executor.json")
    assert _script().main(["--out", str(out), "--doc", str(doc), "--doc-only"]) == 0
    assert doc.read_text() == (DOCS_DIR / "results_executor.md").read_text()
    assert (out / "bench_executor.md").read_text() == doc.read_text()
    assert doc.with_suffix(".json").read_text() == (DOCS_DIR / "results_executor.json").read_text()
    assert (out / "bench_executor.png").stat().st_size > 10_000


def test_rendered_rows_and_spread_follow_the_json():
    r = json.loads((DOCS_DIR / "results_executor.json").read_text())
    r["configs"][0]["wall_s_each"] = [50.0, 150.0]  # a spread of 100 % of a 100 s mean
    r["configs"][0]["wall_s"] = 100.0
    r["identical_results"] = False
    text = render("executor", r)
    rows = [x for x in text.splitlines() if x.startswith("| ") and "workers" not in x]
    assert len(rows) == len(r["configs"]) + 1  # a row per configuration and the cached re-run
    assert rows[0].split("|")[3].strip() == "100.0 (50.0, 150.0)"
    assert "differ by up to 100% of their mean" in text
    assert "byte for byte): **False**." in text


@pytest.mark.slow
def test_bench_executor_end_to_end_on_two_runs(tmp_path):
    pytest.importorskip("ray", reason="the Ray backend needs graphloc[ray]")
    out, doc = tmp_path / "out", tmp_path / "results_executor.md"
    argv = ["--runs", "2", "--repeats", "1", "--speed", "0.1", "--out", str(out)]
    # a process of its own, as it is run: the pools pickle the script's tasks by module
    subprocess.run([sys.executable, str(SCRIPT), *argv, "--doc", str(doc)], check=True)
    r = json.loads((out / "bench_executor.json").read_text())
    assert r == json.loads(doc.with_suffix(".json").read_text())
    assert r["identical_results"] is True and r["runs"] == 2
    assert [(m["backend"], m["workers"]) for m in r["configs"]] == _script().CONFIGS
    assert r["cached_rerun"]["statuses"] == {"cached": 2}
    assert doc.read_text() == render("executor", r, doc="results_executor")
