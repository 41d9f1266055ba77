"""HypothesisTracker vs PoseGraphHypotheses on the same candidate-set streams (issue 51: one
engine?): seed 000 Table III's runs and seed 004's tracks, every run simulated once and fed to
every method (benchmarks.candidate_engines; the adapter: benchmarks.pose_graph_stream). Writes
OUT/bench_candidate_engines.json, the doc's JSON, PNG and markdown
(docs/results_candidate_engines.md, benchmarks.render.candidate_engines).

    nice -n 10 .venv/bin/python scripts/bench_candidate_engines.py --runs 20 \
        --out out/bench_candidate_engines --doc docs/results_candidate_engines.md
    .venv/bin/python scripts/bench_candidate_engines.py --quick      # 3 runs, 4 methods
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # benchmarks/ (the script's helpers, not installed)


def main(argv=None) -> int:
    from tqdm import tqdm

    from benchmarks import candidate_engines as ce
    from benchmarks.render import render

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20, help="runs per cell")
    parser.add_argument("--quick", action="store_true", help="3 runs per cell, 4 methods")
    parser.add_argument("--inputs", nargs="+", default=["feng", "kaushik"])
    parser.add_argument(
        "--methods", nargs="+", help="pose-graph methods beside the tracker (default: all)"
    )
    parser.add_argument(
        "--growth-time", type=float, default=60.0, help="[s] of the long runs (10 updates/s)"
    )
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "bench_candidate_engines")
    parser.add_argument("--doc", type=Path, default=ROOT / "docs" / "results_candidate_engines.md")
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error("--runs must be >= 1")
    runs = 3 if args.quick else args.runs
    unknown = sorted(set(args.methods or ()) - set(ce.ENGINES))
    if unknown:
        parser.error(f"--methods: unknown {unknown}; known: {sorted(ce.ENGINES)}")
    methods = ["tracker", *(args.methods or (ce.QUICK_ENGINES if args.quick else ce.ENGINES))]
    args.out.mkdir(parents=True, exist_ok=True)
    report = {
        "command": ".venv/bin/python scripts/bench_candidate_engines.py "
        + " ".join(argv if argv is not None else sys.argv[1:]),
        "when": time.strftime("%Y-%m-%d %H:%M"),
        "load": " ".join(f"{x:.1f}" for x in os.getloadavg()),
        "runs_per_cell": runs,
        "inputs": args.inputs,
        "kaushik_frames": ce.KAUSHIK_FRAMES,
        "methods": {m: ce.engine_settings(m) for m in methods},
    }
    trials = []
    for trial, cell, index in tqdm(ce.jobs(args.inputs, runs), disable=args.no_progress):
        trials.append(trial(*cell, index, methods))
    growth_time = 20.0 if args.quick else args.growth_time
    report["growth_time_s"] = growth_time
    report["growth"] = [
        ce.growth_run(ceiling, growth_time, method)
        for ceiling in ("level", "sloped")
        for method in tqdm(ce.GROWTH_METHODS, desc=f"long {ceiling} run", disable=args.no_progress)
    ]
    report["rows"] = ce.summarize(trials, methods)
    report["verdict"] = ce.verdict(report["rows"])
    path = args.out / "bench_candidate_engines.json"
    path.write_text(json.dumps({**report, "trials": trials}) + "\n")
    args.doc.with_suffix(".json").write_text(json.dumps(report, indent=1) + "\n")
    ce.plot(report["rows"], args.doc.with_suffix(".png"))
    args.doc.write_text(render("candidate_engines", report, doc=args.doc.stem))
    print(f"wrote {path}, {args.doc}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
