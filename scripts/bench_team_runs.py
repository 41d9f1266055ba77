"""Every scenario through the front door (`graphloc simulate` -> `smooth` / `online`), 20 seeds
per cell, beside today's experiment code: JSON, markdown and PNG (benchmarks.team_runs).

    .venv/bin/python scripts/bench_team_runs.py --out out/bench_team_runs --doc docs/results_team.md

The doc (benchmarks.render.team_runs) and its JSON (the command and the per-cell summary)
are written side by side; `--render` redraws them from OUT/team_runs.json without running.
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.trials import default_backend  # noqa: E402
from graphloc.executor import BACKENDS  # noqa: E402
from benchmarks import team_runs, team_runs_report  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/bench_team_runs"))
    parser.add_argument(
        "--doc", type=Path, default=None, help="also write the markdown tables here"
    )
    parser.add_argument("--size", choices=sorted(team_runs.SIZES), default="full")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--backend", choices=BACKENDS, default="local", help="runs on")
    parser.add_argument("--address", help="--backend ray: 'auto' or HOST:PORT of a cluster")
    parser.add_argument("--seed-offset", type=int, default=0)
    parser.add_argument(
        "--render",
        action="store_true",
        help="only redraw the plot and markdown from OUT/team_runs.json (no runs)",
    )
    args = parser.parse_args(argv)
    command = "scripts/bench_team_runs.py " + " ".join(argv if argv is not None else sys.argv[1:])
    if args.render:  # the doc names the command that ran the saved runs
        team_runs_report.render(args.out, args.doc, command.replace(" --render", ""))
        print(f"rendered {args.out / 'team_runs.json'}")
        return 0
    with default_backend(args.backend, args.address, args.workers):
        rows = team_runs.run(args.size, args.workers, args.seed_offset)
    team_runs_report.write(rows, args.out, args.doc, command)
    print(f"wrote {args.out / 'team_runs.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
