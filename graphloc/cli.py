"""`graphloc VERB ...`: a thin command line. Each verb is a module in graphloc.commands with
HELP (one line), add_arguments(parser) and run(args) -> exit code; the verb parses, calls one
pipeline function and writes outputs. Only verbs that work end to end are listed here."""

from __future__ import annotations

import argparse
import importlib
import sys

from graphloc import __version__

# verb -> module in graphloc.commands (keep sorted by the order a user meets them)
VERBS: dict[str, str] = {
    "demo": "demo",
    "p3p-bench": "p3p_bench",
    "validate": "validate",
    "smooth": "smooth",
    "online": "online",
    "fuse-maps": "fuse_maps",
    "simulate": "simulate",
    "import": "import_bag",
    "reproduce": "reproduce",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="graphloc",
        description="Factor-graph localization of ground + climbing robot teams (GTSAM).",
    )
    parser.add_argument("--version", action="version", version=f"graphloc {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    sub.required = True
    for verb, module_name in VERBS.items():
        module = importlib.import_module(f"graphloc.commands.{module_name}")
        p = sub.add_parser(verb, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except (ValueError, FileNotFoundError) as exc:
        # Bad input: one clear line naming what is wrong, not a traceback from deep inside.
        print(f"graphloc {args.verb}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
