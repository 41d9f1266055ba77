"""`graphloc simulate NAME --out DIR [--seed N] [--FIELD VALUE ...]`: one simulated run, options
from the scenario's config dataclass."""

from __future__ import annotations

import argparse
from pathlib import Path

from graphloc.commands.common import add_common_arguments
from graphloc.config import add_config_arguments, config_from_args, config_values, option_fields
from graphloc.exitcodes import OK

HELP = (
    "simulate a registered scenario into a log directory "
    "(feng-deterministic, feng-probabilistic, ...; NAME --help lists its options)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", help="scenario name (graphloc.datasets registry)")
    parser.add_argument(
        "options",
        nargs=argparse.REMAINDER,
        metavar="--out DIR [--seed N] [--FIELD VALUE ...]",
        help="output run directory, seed and the scenario config's fields (NAME --help)",
    )


def scenario_parser(name: str, config_class: type) -> argparse.ArgumentParser:
    """The options of `graphloc simulate NAME`: --out, --seed and one per config field."""
    parser = argparse.ArgumentParser(
        prog=f"graphloc simulate {name}",
        description=f"write one {name} run ({config_class.__name__} fields as options)",
        exit_on_error=False,
    )
    parser.add_argument("--out", type=Path, help="output run directory (required)")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the run")
    parser.add_argument(
        "--config", type=Path, help="TOML file with any of the fields below (the command line wins)"
    )
    add_config_arguments(parser, config_class, exclude=("seed",))
    add_common_arguments(parser)  # after NAME they reach this parser, not the verb's
    return parser


def run(args: argparse.Namespace) -> int:
    # imported here, not at the top: the simulators load rendering code and Open3D, which
    # `graphloc --help` does not need
    from graphloc.datasets.scenarios import generate, scenario_config_class

    config_class = scenario_config_class(args.name)  # ValueError for unknown names
    parser = scenario_parser(args.name, config_class)
    try:
        opts, rest = parser.parse_known_args(args.options)  # --help prints the fields, exits
    except argparse.ArgumentError as exc:
        raise ValueError(str(exc)) from None
    if rest:
        raise ValueError(
            f"{args.name}: unknown option(s) {' '.join(rest)}; {config_class.__name__} fields: "
            f"{', '.join(option_fields(config_class, exclude=('seed',)))}"
        )
    if not 0 <= opts.seed < 2**32:
        raise ValueError(f"--seed must be an integer in [0, 2**32 - 1], got {opts.seed}")
    overrides = config_values(config_class, opts, exclude=("seed",))
    # the config built once here, so that a value out of its range is named by option or by
    # config file, line and field before anything is simulated
    config_from_args(config_class, opts, exclude=("seed",))
    if opts.out is None:
        raise ValueError(f"{args.name}: --out DIR is required")
    args.out = opts.out  # announced by graphloc.cli when the run is written
    args.quiet = args.quiet or opts.quiet
    path = generate(args.name, opts.out, opts.seed, overrides)
    if not args.quiet:
        print(f"wrote {args.name} (seed {opts.seed}) to {path.parent}")
    return OK
