"""GTSAM 4.3's whole-tree walk in `ISAM2::update`, reproduced without graphloc (issue 15): runs
scripts/isam2_chain_repro.py (a plain Pose2 chain, GTSAM only) under each given Python / GTSAM
install, with GTSAM's default ISAM2Params and with each parameter variant that could avoid the
walk, and writes bench_isam2_chain.json, a PNG of the per-update cost along the chain and,
with --markdown, docs/gtsam_isam2_chain.md (benchmarks.render.isam2_chain, from the JSON)
with the JSON and the PNG beside it.

    .venv/bin/python scripts/bench_isam2_chain.py --python .venv/bin/python \\
        --python OTHER_VENV/bin/python --markdown docs/gtsam_isam2_chain.md

The first --python also runs every ISAM2Params variant; the others run the defaults (with a
prior on every pose, and on the first pose only).
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # the checkout: benchmarks/

import isam2_chain_repro as repro  # noqa: E402
from benchmarks.markdown import write_report  # noqa: E402
from benchmarks.render import render  # noqa: E402
from graphloc.plots import Series, plot_series  # noqa: E402


def run_worker(python: str, poses: int, variant: str, first_prior_only: bool) -> dict:
    cmd = [python, str(HERE / "isam2_chain_repro.py"), "--poses", str(poses)]
    cmd += ["--variant", variant] + (["--first-prior-only"] if first_prior_only else [])
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        tail = (done.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise RuntimeError(f"{Path(python).name} {variant}: exit {done.returncode}: {tail}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--python", action="append", default=None, help="interpreter(s) to run")
    parser.add_argument("--poses", type=int, default=16000)
    parser.add_argument("--out", default="out/bench_isam2_chain")
    parser.add_argument("--markdown", type=Path, default=None)
    parser.add_argument(
        "--from-json", type=Path, default=None, help="no runs: --markdown and its PNG from this"
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    if args.from_json is not None:
        write(json.loads(args.from_json.read_text()), out, args.markdown)
        return 0
    pythons = args.python or [sys.executable]
    runs = []
    for i, python in enumerate(pythons):
        jobs = [(v, False) for v in (repro.VARIANTS if i == 0 else ["defaults"])]
        jobs.append(("defaults", True))
        for variant, first_only in jobs:
            result = run_worker(python, args.poses, variant, first_only)
            runs.append(result)
            print(
                f"{result['gtsam']:38s} {variant:30s} prior every pose "
                f"{result['prior_every_pose']!s:5s} first / last tenth "
                f"{result['first10']['mean_ms']:.3f} / {result['last10']['mean_ms']:.3f} ms",
                flush=True,
            )
    report = {
        "poses": args.poses,
        "cpu_count": os.cpu_count(),
        "load_average_at_end": list(os.getloadavg()),
        "reproduction": inspect.getsource(repro.chain),  # the code the doc shows
        "runs": runs,
    }
    write(report, out, args.markdown)
    return 0


def write(report: dict, out: Path, doc: Path | None) -> None:
    """OUT/bench_isam2_chain.json, .md and the PNG; the doc (`doc`), its JSON and its PNG
    beside it when given."""
    stem = doc.stem if doc is not None else "gtsam_isam2_chain"
    write_report(out, "bench_isam2_chain", report, render("isam2_chain", report, doc=stem), doc,
                 rendered=report)  # fmt: skip
    plot(report, out / "isam2_chain_update_cpu.png")
    if doc is not None:
        plot(report, doc.with_suffix(".png"))
    print(
        f"wrote {out}/bench_isam2_chain.json, .md, PNG" + (f"; {doc} with JSON, PNG" if doc else "")
    )


def plot(r: dict, path: Path) -> None:
    """Per-update CPU along the chain, one curve per run."""
    series = [
        Series(
            f"{x['gtsam']}, {x['variant']}" + ("" if x["prior_every_pose"] else ", first prior"),
            np.array(x["curve_poses"], dtype=float),
            np.array(x["curve_mean_ms"]),
            style="-" if x["variant"] == "defaults" else ":",
        )
        for x in r["runs"]
    ]
    plot_series(
        path,
        series,
        "poses in the tree",
        "CPU per ISAM2 update [ms] (mean of a 1/40 bin)",
        f"Pose2 chain, {r['poses']} poses: per-update cost along the chain",
        logy=True,
    )


if __name__ == "__main__":
    sys.exit(main())
