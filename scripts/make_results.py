"""Regenerate docs/results.md and its JSON: every seed table, paper | seed baseline | graphloc.

Every table through benchmarks.reproduce.make_results (the route scripts/reproduce.py takes
too): its numbers to docs/results.json (the run and one entry per table; `scripts/reproduce.py
TABLE --results docs/results.md` replaces one), docs/results.md rendered from that JSON
(benchmarks.render.results; its last section, every seed table at the stated and the
reproducing reading, from docs/results_seed_baselines.json). `scripts/render_docs.py results.md`
re-renders it without running anything.

    .venv/bin/python scripts/make_results.py            # full size (the run time is in the header)
    .venv/bin/python scripts/make_results.py --quick    # CI size

Outputs (JSON, PNG) go to --out (default out/results); the markdown to --results, its JSON
beside it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from graphloc.executor import BACKENDS  # noqa: E402
from benchmarks.reproduce import make_results  # noqa: E402

HERE = Path(__file__).resolve().parent


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--backend", choices=BACKENDS, default="local", help="trials on")
    parser.add_argument("--address", help="--backend ray: 'auto' or HOST:PORT of a cluster")
    parser.add_argument("--out", type=Path, default=Path("out/results"))
    parser.add_argument(
        "--results",
        type=Path,
        default=HERE.parent / "docs" / "results.md",
        help="the doc; its JSON is written beside it (.json)",
    )
    parser.add_argument(
        "--skip-seed001", action="store_true", help="skip the rendered seed 001 experiment"
    )
    args = parser.parse_args(argv)
    seconds = make_results(
        args.out,
        args.results,
        args.quick,
        args.workers,
        args.skip_seed001,
        backend=args.backend,
        address=args.address,
    )
    print(f"wrote {args.results} ({seconds:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
