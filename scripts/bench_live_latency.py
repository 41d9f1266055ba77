"""Live latency (issue 50; benchmarks/live_latency.py says what is measured and how): per-step
latency of the live API against the team size (1, 2, 5, 10 robots) and end to end over ROS 2
(row published -> pose received) for MRCLAM Dataset6's five robots. Writes
OUT/results_live_latency.{json,md} and docs/results_live_latency.{md,json,png}
(benchmarks.render.live_latency; `scripts/render_docs.py results_live_latency.md` re-renders
the doc from the committed JSON).

    .venv/bin/python scripts/bench_live_latency.py --duration 120

A measurement, not a test: the target (end-to-end p95 under 20 ms) is read off the doc."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.live_latency import DATASET6, plot, run  # noqa: E402
from benchmarks.markdown import write_report  # noqa: E402
from benchmarks.render import DOCS_DIR, render  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--duration", type=float, default=120.0, help="s of Dataset6 (default 120)")
    p.add_argument("--rate", type=float, default=1.0, help="publication pace (1: as recorded)")
    p.add_argument("--out", type=Path, default=Path("out/bench_live_latency"))
    p.add_argument("--no-doc", action="store_true", help="leave docs/ as it is")
    args = p.parse_args(argv)
    if not DATASET6.is_dir():
        print(f"bench_live_latency: error: {DATASET6}: no MRCLAM Dataset6", file=sys.stderr)
        return 2
    result = run(args.duration, args.out, args.rate)
    result["command"] = "scripts/bench_live_latency.py " + " ".join(argv or sys.argv[1:])
    png = (args.out if args.no_doc else DOCS_DIR) / "results_live_latency.png"
    plot(result, png)
    api = DOCS_DIR / "results_live.json"  # scripts/bench_live.py's, rendered beside
    api = json.loads(api.read_text()) if api.is_file() else None
    text = render("live_latency", result, api, doc="results_live_latency")
    doc = None if args.no_doc else DOCS_DIR / "results_live_latency.md"
    write_report(args.out, "results_live_latency", result, text, doc, rendered=result)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
