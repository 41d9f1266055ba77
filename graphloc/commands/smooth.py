"""`graphloc smooth RUN --out DIR`: batch smoothing of a team's run (log directory, MRCLAM
directory or bag) with `RunOptions` from the command line and `--config FILE`."""

from __future__ import annotations

import argparse
import contextlib
import importlib.machinery
import os
import signal
import sys
import threading
from pathlib import Path

from graphloc import many_runs
from graphloc.commands.common import Interrupted, verdict_exit
from graphloc.exitcodes import INCOMPLETE, INTERRUPTED, OutputDropped
from graphloc.config import add_config_arguments, config_from_args
from graphloc.pipelines.team_graph.options import RunOptions
from graphloc.structured import dumps_json

HELP = (
    "batch factor-graph smoothing of a team's run (log dir or MRCLAM dir): TUM, metrics JSON, PNGs"
)
MODE = "batch"
EXIT_STOPPED = INCOMPLETE  # SIGINT / SIGTERM: the outputs so far were written, metrics partial


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options shared by `smooth` and `online`."""
    parser.add_argument(
        "run",
        nargs="*",
        help="graphloc log directory (manifest.json) or MRCLAM dataset directory; several "
        "runs or a quoted glob: each is one task of graphloc.many_runs (DIR/<run>/, runs.csv)",
    )
    many_runs.add_arguments(parser)
    parser.add_argument("--out", required=True, type=Path, help="output directory")
    parser.add_argument("--config", type=Path, help="TOML file with any of the options below")
    add_config_arguments(parser, RunOptions)


def options(args: argparse.Namespace) -> RunOptions:
    """Effective options: defaults < --config file < command line (`RunOptions`)."""
    return config_from_args(RunOptions, args)


class StopFlag:
    """SIGINT / SIGTERM during `smooth` / `online`, by `phase`: "reading" ends at once (130),
    "solving" stops after the current step and writes the outputs so far (3), "writing" finishes
    them but drops a figure being drawn (`droppable`); a second signal ends at once
    (docs/design_core.md, "Stopping")."""

    RETRY_S = 0.02

    def __init__(self, verb: str = "smooth"):
        self.verb = verb
        self.signal: int | None = None
        self.phase = "reading"
        self._old: dict = {}
        self._pending: int | None = None
        self._droppable = False

    def __call__(self) -> bool:
        return self.signal is not None

    @contextlib.contextmanager
    def droppable(self):
        """While the block runs, a first signal in the writing phase raises `OutputDropped`
        in it (the output it writes may be left out) instead of letting it finish."""
        self._droppable = True
        try:
            yield
        finally:
            self._droppable = False

    @staticmethod
    def _initializing_extension(frame) -> bool:
        """Whether the stack holds an import in progress: a C extension's initialization (its
        loader's create_module or exec_module), or the import system's own machinery, whose
        callbacks (a module lock's weakref callback) swallow an exception raised there."""
        while frame is not None:
            if getattr(frame.f_code, "co_filename", "").startswith("<frozen importlib"):
                return True
            if frame.f_code.co_name in ("create_module", "exec_module") and isinstance(
                frame.f_locals.get("self"), importlib.machinery.ExtensionFileLoader
            ):
                return True
            frame = frame.f_back
        return False

    def _retry(self, signum, frame):
        pending, self._pending = self._pending, None
        if pending is not None:
            self._handle(pending, frame)

    def _handle(self, signum, frame):
        name = signal.Signals(signum).name
        reading = (
            f"{name} while reading the run or building the graph: stopped before any "
            "estimate, nothing written"
        )
        if self._initializing_extension(frame):
            if self.phase == "reading":  # nothing written: no need to wait for the import
                from graphloc.names import release_claims

                release_claims()
                print(f"graphloc {self.verb}: error: {reading}", file=sys.stderr, flush=True)
                sys.stdout.flush()
                os._exit(INTERRUPTED)
            if hasattr(signal, "setitimer"):
                self._pending = signum
                signal.setitimer(signal.ITIMER_REAL, self.RETRY_S)
                return
        if self.phase == "reading":
            raise Interrupted(reading)
        if self.signal is not None:
            raise Interrupted(f"{name} again: stopped at once; the outputs may be incomplete")
        self.signal = signum
        if self.phase == "solving":
            said = (
                "finishing the current step, then writing the outputs so far "
                f"(exit code {EXIT_STOPPED})"
            )
        else:
            said = "finishing writing the outputs"
        print(f"\n{name}: {said}; a second signal stops at once", file=sys.stderr, flush=True)
        if self._droppable and self.phase == "writing":
            self._droppable = False
            raise OutputDropped(name)

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
            if hasattr(signal, "SIGALRM"):
                self._old[signal.SIGALRM] = signal.signal(signal.SIGALRM, self._retry)
        return self

    def __exit__(self, *exc):
        if getattr(signal, "SIGALRM", None) in self._old:
            signal.setitimer(signal.ITIMER_REAL, 0)  # a retry not yet due
        for sig, old in self._old.items():
            signal.signal(sig, old)
        return False


def run_verb(args: argparse.Namespace, mode: str, checkpoint=None) -> int:
    """The whole verb: `runner.team_run.run_team` under SIGINT / SIGTERM handling by phase
    (`StopFlag`), then the summary, the verdict's lines and the exit code."""
    progress = not args.no_progress
    from graphloc.commands import pose_graph_run

    verb = "smooth" if mode == "batch" else "online"
    if pose_graph_run.is_pose_graph_file(args.run):  # City10000 / g2o: the pose-graph engine
        return pose_graph_run.run_verb(args, mode, options(args), lambda: StopFlag(verb))
    with StopFlag(verb) as stop:
        opts = options(args)
        pose_graph_run.reject_options(opts.pose_graph(), args.run)
        from graphloc.runner.team_run import run_team

        metrics = run_team(
            args.run,
            args.out,
            mode,
            opts,
            stop=stop,
            checkpoint=checkpoint,
            progress=progress,
            on_phase=lambda phase: setattr(stop, "phase", phase),
        ).metrics
        ate = many_runs.ate_by_robot(metrics, mode)
        summary = {
            "mode": mode,
            "partial": metrics["partial"],
            "consistent": metrics["consistent"],
            "ate_rmse_m": {name: round(v, 4) for name, v in ate.items()},
            "decisions": metrics["decisions"],
            "realtime_factor": round(metrics["realtime_factor"], 1),
            "skipped": metrics["skipped"]["counts"],
            "notes": metrics["notes"]["counts"],
            "landmark_map": metrics["landmark_map"],
        }
        if metrics["skipped_outputs"]:
            summary["skipped_outputs"] = metrics["skipped_outputs"]
        print(dumps_json(summary, indent=1))
    partial = bool(metrics["partial"] or metrics["skipped_outputs"])
    return verdict_exit(verb, args, metrics["consistency"], partial, opts.strict)


def run(args: argparse.Namespace) -> int:
    return many_runs.dispatch(args, MODE, run_verb)
