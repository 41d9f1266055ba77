"""Every doc of benchmarks.render.DOCS is what its committed JSON renders to: a changed
renderer, template or JSON without the doc re-rendered (scripts/render_docs.py) fails here."""

from __future__ import annotations

import pytest

from benchmarks.render import DOCS, DOCS_DIR, markdown_table, render_doc


@pytest.mark.parametrize("name", sorted(DOCS))
def test_doc_is_its_json_rendered(name):
    assert render_doc(name) == (DOCS_DIR / name).read_text()


def test_markdown_table_prints_cells_as_given():
    import pandas as pd

    text = markdown_table(pd.DataFrame([["0.50", 3]], columns=["a [m]", "n"]))
    assert text.splitlines() == ["| a [m]   | n   |", "|:--------|:----|", "| 0.50    | 3   |"]


def test_reflow_joins_paragraphs_and_list_items_only():
    from benchmarks.render import reflow

    text = "# A\n\nsome\nprose.\n\n| a |\n| b |\n\n- one\n  more\n- two\n\n    code\n    kept\n"
    assert (
        reflow(text)
        == "# A\n\nsome prose.\n\n| a |\n| b |\n\n- one more\n- two\n\n    code\n    kept\n"
    )
    fenced = "```python\ndef f():\n    a = 1\n\n    return a\n```\n\nafter\nit\n"
    assert reflow(fenced) == "```python\ndef f():\n    a = 1\n\n    return a\n```\n\nafter it\n"


def test_speed_doc_says_whether_a_probe_variant_meets_the_mrclam_target():
    """results_speed.md's verdict on MRCLAM online follows the probe's numbers: blocked while
    no variant reaches 300x with every robot's ATE within 1 %, met by one that does."""
    import json

    from benchmarks.render import render

    report = json.loads((DOCS_DIR / "results_speed.json").read_text())
    probe = json.loads((DOCS_DIR / "results_mrclam_pose2.json").read_text())
    assert "No variant reaches 300x" in render("speed", report, probe, doc="results_speed")
    fast = dict(probe["variants"][1], end_to_end_realtime_factor=310.0)
    probe["variants"].append(dict(fast, worst_ate_over_graphloc=1.02))  # fast, ATE off
    assert "No variant reaches 300x" in render("speed", report, probe, doc="results_speed")
    probe["variants"].append(dict(fast, worst_ate_over_graphloc=1.005))
    text = render("speed", report, probe, doc="results_speed")
    assert "1 variant(s) reach 300x" in text and "No variant reaches" not in text
