"""The results docs (docs/results*.md), each rendered from its committed JSON: one module
here per doc family whose `context(...)` turns the JSON into the values and pandas tables
its Jinja2 template (templates/<renderer>.md.j2, the prose) prints. `DOCS` names every
rendered doc with its renderer and the JSON files in docs/ it reads; the benchmarks call
`render` on the result they have just written, `scripts/render_docs.py` re-renders a doc from
its committed JSON without running anything (tests/reproductions/test_results_docs.py: every doc as
committed)."""

from __future__ import annotations

import importlib
import json
from dataclasses import dataclass
from pathlib import Path

import jinja2
import pandas as pd

DOCS_DIR = Path(__file__).resolve().parents[2] / "docs"
TEMPLATES = Path(__file__).resolve().parent / "templates"


@dataclass(frozen=True)
class Doc:
    """A rendered doc: the module of benchmarks.render (and template) that renders it, and
    the JSON files of docs/ handed to its `context`, in that order."""

    renderer: str
    inputs: tuple[str, ...]


DOCS = {
    "gtsam_isam2_chain.md": Doc("isam2_chain", ("gtsam_isam2_chain.json",)),
    "results_candidate_engines.md": Doc("candidate_engines", ("results_candidate_engines.json",)),
    "results_city10000.md": Doc("city10000", ("results_city10000.json",)),
    "results_executor.md": Doc("executor", ("results_executor.json",)),
    "results_fusion_envelope.md": Doc("fusion_envelope", ("results_fusion_envelope.json",)),
    "results_g2o_outliers.md": Doc("g2o_outliers", ("results_g2o_outliers.json",)),
    "results_g2o_outliers_sphere2500.md": Doc(
        "g2o_outliers", ("results_g2o_outliers_sphere2500.json",)
    ),
    "results_scale.md": Doc("scale", ("results_scale.json",)),
    "results_startup.md": Doc("startup", ("results_startup.json",)),
    "results_team.md": Doc("team_runs", ("results_team.json",)),
    "results_speed.md": Doc("speed", ("results_speed.json", "results_mrclam_pose2.json")),
    "results_live_latency.md": Doc(
        "live_latency", ("results_live_latency.json", "results_live.json")
    ),
    "results_team_crawler.md": Doc("team_crawler", ("results_team_crawler.json",)),
    "results_team_dual_room.md": Doc("team_dual_room", ("results_team_dual_room.json",)),
    "results_seed_baselines.md": Doc("seed_baselines", ("results_seed_baselines.json",)),
    "results_seed003.md": Doc("seed003", ("results_seed003.json",)),
    "results_seed003_heldout.md": Doc("seed003", ("results_seed003_heldout.json",)),
    "results.md": Doc("results", ("results.json", "results_seed_baselines.json")),
    "results_fusion_real.md": Doc(
        "fusion_real", ("results_fusion_real.json", "results_fusion_calibration.json")
    ),
    "results_fusion_real_redwood.md": Doc(
        "fusion_real", ("results_fusion_real_redwood.json", "results_fusion_calibration.json")
    ),
}


def header(columns: str) -> list[str]:
    """A table's column names written as its markdown header row: "a | b [m] | c"."""
    return columns.split(" | ")


def markdown_table(frame: pd.DataFrame) -> str:
    """A DataFrame as a markdown (pipe) table, its cells printed as given (the renderers
    format the numbers)."""
    return frame.astype(str).to_markdown(index=False, tablefmt="pipe", disable_numparse=True)


_ENV = jinja2.Environment(
    loader=jinja2.FileSystemLoader(TEMPLATES),
    undefined=jinja2.StrictUndefined,
    keep_trailing_newline=True,
    trim_blocks=True,
    lstrip_blocks=True,
)
_ENV.filters["table"] = markdown_table
_ENV.filters["g"] = lambda x: f"{x:g}"
_ENV.filters["f2"] = lambda x: f"{x:.2f}"


def reflow(markdown: str) -> str:
    """Each paragraph and list item of `markdown` on one line (the templates wrap their prose);
    tables, headings, images, indented and fenced code as they are."""
    body = markdown.rstrip("\n")
    blocks, fenced = [], False  # fenced: inside a ``` code block (blank lines in it)
    for block in body.split("\n\n"):
        lines = block.split("\n")
        if fenced or block.startswith(("|", "#", "![", "    ", "```")) or not block.strip():
            blocks.append(block)
            fenced ^= block.count("```") % 2 == 1
        elif block.startswith("- "):  # a list: continuation lines join their item
            items = []
            for line in lines:
                if line.startswith("- ") or not items:
                    items.append(line)
                else:
                    items[-1] += " " + line.strip()
            blocks.append("\n".join(items))
        else:
            blocks.append(" ".join(line.strip() for line in lines))
    return "\n\n".join(blocks) + markdown[len(body) :]


def render(renderer: str, *data, doc: str = "") -> str:
    """The markdown of benchmarks.render.<renderer> for its JSON documents `data`; `doc`: the
    doc's file stem, for a template that names the files beside it."""
    context = importlib.import_module(f"{__name__}.{renderer}").context(*data)
    return reflow(_ENV.get_template(f"{renderer}.md.j2").render(context, doc=doc))


def render_doc(name: str, docs_dir: Path = DOCS_DIR) -> str:
    """The markdown of docs/`name` from the JSON files it is rendered from."""
    doc = DOCS[name]
    data = [json.loads((docs_dir / f).read_text()) for f in doc.inputs]
    return render(doc.renderer, *data, doc=Path(name).stem)
