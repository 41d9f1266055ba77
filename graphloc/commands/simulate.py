"""`graphloc simulate NAME --out DIR [--seed N] [--set KEY=VALUE ...]`: write one simulated run
(log format + 3D ground truth, graphloc.datasets.scenarios)."""

from __future__ import annotations

from pathlib import Path

HELP = (
    "simulate a registered scenario into a log directory "
    "(feng-deterministic, feng-probabilistic, ...)"
)


def add_arguments(parser) -> None:
    parser.add_argument("name", help="scenario name (graphloc.datasets registry)")
    parser.add_argument("--out", type=Path, required=True, help="output run directory")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a field of the scenario's config dataclass (repeatable)",
    )


def run(args) -> int:
    # imported here, not at the top: the simulators load rendering code and Open3D, which
    # `graphloc --help` does not need
    from graphloc.datasets.scenarios import generate

    overrides = {}
    for item in args.overrides:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"--set expects KEY=VALUE, got {item!r}")
        overrides[key.strip()] = value.strip()
    path = generate(args.name, args.out, args.seed, overrides)
    print(f"wrote {args.name} (seed {args.seed}) to {path}")
    return 0
