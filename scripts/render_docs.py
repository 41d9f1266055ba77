"""Re-render docs/results*.md from their committed JSON, without running any benchmark
(benchmarks.render: one renderer and template per doc).

    .venv/bin/python scripts/render_docs.py              # every doc of benchmarks.render.DOCS
    .venv/bin/python scripts/render_docs.py results_fusion_real.md
    .venv/bin/python scripts/render_docs.py --check      # exit 1 if a doc differs from its JSON
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.render import DOCS, DOCS_DIR, render_doc  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("docs", nargs="*", help=f"of {', '.join(DOCS)} (default: every one)")
    parser.add_argument("--check", action="store_true", help="compare, do not write")
    args = parser.parse_args(argv)
    unknown = [name for name in args.docs if name not in DOCS]
    if unknown:
        parser.error(f"no renderer for {', '.join(unknown)}; choose from {', '.join(DOCS)}")
    stale = []
    for name in args.docs or DOCS:
        text, path = render_doc(name), DOCS_DIR / name
        if args.check:
            if not path.is_file() or path.read_text() != text:
                stale.append(name)
            continue
        path.write_text(text)
        print(f"wrote {path}")
    for name in stale:
        print(f"{name} differs from its JSON's rendering", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    raise SystemExit(main())
