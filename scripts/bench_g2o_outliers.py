"""Outlier loop closures on public g2o pose graphs (issue 51): `rate` x (the file's loop
closures) random false loop closures injected (seeded; benchmarks/g2o_outliers.py), then
graphloc's multi-hypothesis engine online (every loop closure with a null component) and GNC
(gtsam.GncLMOptimizer, TLS, batch, odometry known inliers) in the same run, each against the
optimum of the graph without outliers: position RMSE, outliers accepted, inliers rejected, CPU
time, graphloc's per-step CPU. Writes JSON, a PNG and docs/results_g2o_outliers.md.

The graphs are not in the repository: Intel, Manhattan (Olson, g2o) and sphere2500 ship with
Suenderhauf's Vertigo (github.com/OpenSLAM-org/openslam_vertigo, datasets/*/originalDataset/).

    .venv/bin/python scripts/bench_g2o_outliers.py --graphs DIR/intel.g2o \
        DIR/manhattanOlson3500.g2o DIR/sphere2500.g2o --rates 0.1 0.3 0.5 \
        --out out/bench_g2o_outliers --doc docs/results_g2o_outliers.md
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


def run_graph(path: Path, rates, seed: int, progress: bool) -> list[dict]:
    import numpy as np
    from tqdm import tqdm

    from benchmarks import g2o_outliers as go

    graph = go.load(path)
    ids = sorted({k for m in graph.measurements for k in (m.source, m.target)})
    start = time.process_time()
    reference = go.reference(graph)
    ref_cpu = time.process_time() - start
    ref, inliers = go.positions(reference, ids, graph.dim), go.inlier_graph(graph)
    reference_error = inliers.error(reference)
    rows = []
    for rate in rates:
        measurements, fake = go.inject(graph, rate, seed)
        bar = tqdm(total=len(ids), disable=not progress, desc=f"{path.stem} {rate:g}", leave=False)
        results = {"graphloc": go.run_graphloc(graph, measurements, bar), "gnc": None}
        bar.close()
        results["gnc"] = go.run_gnc(graph, measurements)
        for name, r in results.items():
            xy = go.positions(r["values"], ids, graph.dim)
            accepted = r["accepted"]
            row = {
                "graph": path.stem, "dim": graph.dim, "poses": len(ids), "rate": rate,
                "outliers": int(sum(fake)), "method": name,
                "rmse_m": float(np.sqrt(np.mean(np.sum((xy - ref) ** 2, axis=1)))),
                "outliers_accepted": int(sum(accepted[i] for i in accepted if fake[i])),
                "inliers_rejected": int(sum(not accepted[i] for i in accepted if not fake[i])),
                "objective_above_reference": inliers.error(r["values"]) - reference_error,
                "cpu_s": r["cpu"], "reference_cpu_s": ref_cpu,
            }  # fmt: skip
            if r.get("times"):
                t = np.asarray(r["times"]) * 1e3
                row.update(step_p50_ms=float(np.median(t)), step_p95_ms=float(np.percentile(t, 95)))
            rows.append(row)
        print(_summary(rows[-2:]), flush=True)
    return rows


def _summary(rows) -> str:
    return " | ".join(
        f"{r['graph']} {r['rate']:g} {r['method']}: {r['rmse_m']:.3g} m, "
        f"{r['outliers_accepted']}/{r['outliers']} accepted, {r['inliers_rejected']} inliers "
        f"rejected, {r['cpu_s']:.1f} s"
        for r in rows
    )


def render(report: dict, doc: Path) -> None:
    """The doc's JSON, PNG and markdown (benchmarks.render.g2o_outliers) of a run's report."""
    import pandas as pd

    from benchmarks.render import render as render_doc
    from graphloc.plots import Series, plot_series

    frame = pd.DataFrame(report["rows"])
    series = []
    for (graph, method), part in frame.groupby(["graph", "method"]):
        style = "o-" if method == "graphloc" else "s--"
        rates, rmse = part["rate"].to_numpy(), part["rmse_m"].to_numpy()
        series.append(Series(f"{graph} {method}", rates, rmse, style=style))
    plot_series(doc.with_suffix(".png"), series, xlabel="injected outliers / loop closures",
                ylabel="position RMSE vs outlier-free optimum [m]", logy=True,
                title="g2o graphs with injected outlier loop closures")  # fmt: skip
    doc.with_suffix(".json").write_text(json.dumps(report, indent=1) + "\n")
    doc.write_text(render_doc("g2o_outliers", report, doc=doc.stem))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--graphs", type=Path, nargs="+", required=False, default=[])
    parser.add_argument("--rates", type=float, nargs="+", default=[0.1, 0.3, 0.5])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--note", action="append", default=[])
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "bench_g2o_outliers")
    parser.add_argument("--doc", type=Path, default=ROOT / "docs" / "results_g2o_outliers.md")
    parser.add_argument("--render", action="store_true", help="only the doc from the JSON")
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "bench_g2o_outliers.json"
    if not args.render:
        if not args.graphs:
            parser.error("--graphs: at least one g2o file")
        report = {
            "command": ".venv/bin/python scripts/bench_g2o_outliers.py "
            + " ".join(argv if argv is not None else sys.argv[1:]),
            "when": time.strftime("%Y-%m-%d %H:%M"),
            "load": " ".join(f"{x:.1f}" for x in os.getloadavg()),
            "seed": args.seed, "notes": args.note, "rows": [],
        }  # fmt: skip
        for graph in args.graphs:  # the JSON after each graph: a stopped run keeps the others
            report["rows"] += run_graph(graph, args.rates, args.seed, not args.no_progress)
            path.write_text(json.dumps(report) + "\n")
    report = json.loads(path.read_text())
    if args.render and args.note:
        report["notes"] = args.note
        path.write_text(json.dumps(report) + "\n")
    render(report, args.doc)
    print(f"wrote {path}, {args.doc}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
