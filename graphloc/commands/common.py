"""The options every verb takes: `-v` / `-q` and `--no-progress`."""

from __future__ import annotations

import argparse
import logging
import sys

from graphloc.exitcodes import INCOMPLETE, INCONSISTENT, OK

LOG = logging.getLogger("graphloc")


class Interrupted(KeyboardInterrupt):
    """A signal that ends a verb at once; its message says when and what was written
    (`graphloc.cli.main`: one `error:` line, exit code INTERRUPTED)."""


def add_common_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("common options")
    talk = group.add_mutually_exclusive_group()
    talk.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=0,
        help="the effective options and the wall time on stderr (-vv: debug logging)",
    )
    talk.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="only errors: no summary, no progress bars, no output folder line",
    )
    group.add_argument("--no-progress", action="store_true", help="no progress bars")


def progress(args: argparse.Namespace) -> bool:
    """Whether a verb shows progress bars."""
    return not (getattr(args, "no_progress", False) or getattr(args, "quiet", False))


def configure_logging(verbose: int) -> None:
    """graphloc's log on stderr: warnings by default, INFO with -v, DEBUG (every library's
    log) with -vv."""
    level = logging.WARNING if verbose == 0 else logging.INFO if verbose == 1 else logging.DEBUG
    logging.basicConfig(format="%(name)s: %(message)s", force=True)
    LOG.setLevel(level)
    if verbose >= 2:
        logging.getLogger().setLevel(logging.DEBUG)


def verdict_exit(verb: str, args, verdict: dict, partial: bool, strict: bool) -> int:
    """The consistency verdict's lines on stderr (unless -q), then the verb's exit code:
    INCOMPLETE for a stopped run, INCONSISTENT with --strict, else OK."""
    if not getattr(args, "quiet", False):
        for line in verdict["failures"]:
            print(f"graphloc {verb}: inconsistent: {line}", file=sys.stderr)
        for line in verdict["warnings"]:
            print(f"graphloc {verb}: warning: {line}", file=sys.stderr)
    if partial:
        return INCOMPLETE
    return INCONSISTENT if strict and (verdict["failures"] or verdict["warnings"]) else OK
