"""One table of docs/results.md alone (`scripts/reproduce.py TABLE` prints it): its entry of
docs/results.json through the table's template, as benchmarks.render.results renders it in the
doc. Template: templates/results_section.md.j2."""

from __future__ import annotations

from benchmarks.render.results import section


def context(name: str, entry: dict) -> dict:
    return {"s": section(name, entry)}
