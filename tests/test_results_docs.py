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
