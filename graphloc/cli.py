"""`graphloc VERB ...`: each verb is a module in graphloc.commands with HELP, add_arguments(parser)
and run(args) -> exit code. `main` is the one place where failures become exit codes
(`graphloc.exitcodes`, docs/outputs.md): bad input is one `error:` line and BAD_INPUT, an OS or
solver error FAILED, Ctrl-C INTERRUPTED; no expected failure ends in a traceback."""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import os
import signal
import sys
import time
from pathlib import Path

from graphloc import __version__
from graphloc.commands.common import LOG, add_common_arguments, configure_logging
from graphloc.names import claim_out
from graphloc.exitcodes import (
    BAD_INPUT,
    FAILED,
    INCOMPLETE,
    INCONSISTENT,
    INTERRUPTED,
    OK,
    SolverFailure,
)

# verb -> module in graphloc.commands (keep sorted by the order a user meets them)
VERBS: dict[str, str] = {
    "demo": "demo",
    "validate": "validate",
    "smooth": "smooth",
    "online": "online",
    "live": "live",
    "fuse-maps": "fuse_maps",
    "simulate": "simulate",
    "import": "import_bag",
}


def build_parser(load=None) -> argparse.ArgumentParser:
    """The command line: every verb with its options, or, with `load` (verbs of VERBS), those
    verbs' options alone, the others named but not imported. `main` loads the verb the command
    line names (none for `--version`, every verb for the program's `--help`), so a verb starts
    without importing the other verbs' modules."""
    parser = argparse.ArgumentParser(
        prog="graphloc",
        description="Factor-graph localization of ground + climbing robot teams (GTSAM).",
    )
    parser.add_argument("--version", action="version", version=f"graphloc {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    sub.required = True
    for verb, module_name in VERBS.items():
        if load is not None and verb not in load:
            sub.add_parser(verb)
            continue
        module = importlib.import_module(f"graphloc.commands.{module_name}")
        p = sub.add_parser(verb, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        add_common_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def verbs_to_load(argv: list[str]) -> list[str] | None:
    """The verbs `main` loads for a command line: the verb it names (its first word that is
    not an option: the program's own options take no value), else none -- `--version`, or a
    usage error -- unless it asks for the program's help (every verb, None)."""
    word = next((a for a in argv if not a.startswith("-")), None)
    if word in VERBS:
        return [word]
    return None if word is None and {"-h", "--help"} & set(argv) else []


def check_out(out: Path) -> None:
    """--out must be a directory graphloc can create or write, checked before any computation
    (ValueError naming the option otherwise)."""
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out}: exists and is not a directory")
    parent = next((p for p in [out, *out.parents] if p.exists()), Path("."))
    if not parent.is_dir():
        raise ValueError(f"--out {out}: {parent} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"--out {out}: {parent} is not writable")


def main(argv: list[str] | None = None) -> int:
    program = argv is None  # the process itself (the console script, python -m graphloc)
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        return _main(argv)
    except KeyboardInterrupt as exc:  # before a verb runs (its options read) or after it ended
        verb = next((a for a in argv if a in VERBS), "")
        text = str(exc) or "interrupted (Ctrl-C)"
        print(f"graphloc{' ' + verb if verb else ''}: error: {text}", file=sys.stderr)
        return INTERRUPTED
    finally:
        if program:  # exiting with its code: a Ctrl-C now would only turn it into "killed"
            signal.signal(signal.SIGINT, signal.SIG_IGN)


def _main(argv: list[str]) -> int:
    args = build_parser(verbs_to_load(argv)).parse_args(argv)

    def error(text: str, code: int) -> int:
        print(f"graphloc {args.verb}: error: {text}", file=sys.stderr)
        return code

    if args.quiet:
        args.no_progress = True
    configure_logging(args.verbose)
    shown = {k: v for k, v in sorted(vars(args).items()) if not k.startswith("_")}
    LOG.info("%s: options %s", args.verb, shown)
    start = time.perf_counter()
    try:
        held = contextlib.nullcontext()
        if getattr(args, "out", None) is not None:
            check_out(Path(args.out))
            held = claim_out(args.out)
        quiet = (
            contextlib.redirect_stdout(io.StringIO()) if args.quiet else contextlib.nullcontext()
        )
        with held, quiet:
            code = int(args._run(args) or OK)
    except SolverFailure as exc:  # the input was read, GTSAM could not solve it
        return error(f"the solver failed: {exc}", FAILED)
    except (ValueError, FileNotFoundError) as exc:
        # Bad input: one clear line naming what is wrong, not a traceback from deep inside.
        return error(str(exc), BAD_INPUT)
    except KeyboardInterrupt as exc:  # Ctrl-C, or `Interrupted` saying when and what was written
        return error(str(exc) or "interrupted (Ctrl-C); outputs may be incomplete", INTERRUPTED)
    except OSError as exc:  # disk full, permissions, a path that is not a directory, ...
        return error(f"{exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), FAILED)
    except RuntimeError as exc:  # Open3D and GTSAM report their failures as RuntimeError
        return error(f"{type(exc).__name__}: {exc}", FAILED)
    LOG.info("%s: exit %d after %.1f s", args.verb, code, time.perf_counter() - start)
    out = getattr(args, "out", None)
    done = (OK, INCOMPLETE, INCONSISTENT)
    if out is not None and code in done and Path(out).is_dir() and not args.quiet:
        print(f"graphloc {args.verb}: outputs in {out}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
