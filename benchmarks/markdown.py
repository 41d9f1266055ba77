"""The one writer of a benchmark's JSON + markdown (`write_report`); the seeds' tables
(docs/results.md) are rendered by benchmarks.render.results."""

from __future__ import annotations

from pathlib import Path
from graphloc.structured import dumps_json


def write_report(
    out: Path, stem: str, payload: dict, text: str, doc: Path | None = None, rendered=None
) -> None:
    """A benchmark's OUT/STEM.json (payload) and OUT/STEM.md (text); the markdown also at `doc`
    (a generated page in docs/) when given, with `rendered` -- the JSON it was rendered from --
    beside it (DOC.json, which scripts/render_docs.py renders the doc from)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{stem}.json").write_text(dumps_json(payload, indent=1))
    (out / f"{stem}.md").write_text(text)
    if doc is not None:
        doc.write_text(text)
        if rendered is not None:
            doc.with_suffix(".json").write_text(dumps_json(rendered, indent=1) + "\n")
