"""`graphloc smooth RUN --out DIR`: batch smoothing (Levenberg-Marquardt over the whole factor
graph) of a team's run -- a graphloc log directory (every table: odometry, relative poses,
bearings, ranges, range-bearing, markers -> P3P candidate sets, surfaces) or an MRCLAM dataset
directory (`graphloc.datasets.open_run`, `graphloc.pipelines.team_graph`). Writes per-robot
TUM trajectories, metrics.json, decisions.csv and PNG plots (docs/outputs.md).

Options are the fields of `graphloc.pipelines.team_graph.options.RunOptions`, from the command
line and from `--config FILE` (TOML, the field names); the command line wins. Sensor noise
options replace what the log's sensor params state; left unset, the log's values (or graphloc's
defaults) hold."""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from pathlib import Path

from graphloc import many_runs
from graphloc.exitcodes import INCOMPLETE, OK
from graphloc.manifest import check_noise_params
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


def landmark_map(run, config) -> str:
    """Where the landmark positions come from, said explicitly (metrics.json, printed): a run
    with landmark measurements but no landmark file is solved as SLAM, never silently."""
    if not config.use_landmarks or not any(p.landmark >= 0 for p in run.points):
        return "none: no landmark measurements used"
    if not run.landmarks_known:
        return "estimated (SLAM): the run has no landmark file"
    if not config.landmark_priors:
        return "estimated (SLAM): --unknown-landmarks"
    return f"known: {len(run.landmark_ids)} landmarks from the run's landmark file"


class StopFlag:
    """SIGINT / SIGTERM set the flag (the solve finishes its step and stops); a second SIGINT
    interrupts at once. Installed for the duration of a `with` block."""

    def __init__(self):
        self.signal: int | None = None
        self._old: dict = {}

    def __call__(self) -> bool:
        return self.signal is not None

    def _handle(self, signum, frame):
        if self.signal is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt
        self.signal = signum
        print(
            f"\n{signal.Signals(signum).name}: finishing the current step, then writing the "
            f"outputs so far (exit code {EXIT_STOPPED})",
            file=sys.stderr,
            flush=True,
        )

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc):
        for sig, old in self._old.items():
            signal.signal(sig, old)
        return False


def run_verb(args: argparse.Namespace, mode: str, checkpoint=None) -> int:
    """The whole verb: outputs checked, run read, graph built, solved (stoppable, with an
    online checkpoint / resume hook from `graphloc.commands.online`), evaluated, written."""
    from dataclasses import asdict, replace

    from graphloc.datasets import open_run
    from graphloc.pipelines.recording import team_recording, write_recordings
    from graphloc.pipelines.report import evaluate, write_outputs
    from graphloc.pipelines.team_graph import build_graph, default_lag, solve

    opts = options(args)
    values = asdict(opts)
    config = opts.graph_config()
    progress = not args.no_progress
    with StopFlag() as stop:
        noise = opts.noise()
        check_noise_params(noise, "option (command line or --config)")
        run = open_run(args.run, duration=opts.duration, noise=noise, source=opts.source())
        lag = opts.lag if opts.lag is not None else default_lag(run, config)
        config = replace(config, lag=float(lag))
        graph = build_graph(run, config, progress=progress)
        hooks = checkpoint(graph, values) if checkpoint is not None else {}
        result = solve(graph, mode=mode, progress=progress, stop=stop, **hooks)
        metrics = evaluate(result, run)
        metrics["config"] = json.loads(dumps_json(asdict(config), default=str))
        metrics["options"] = values
        metrics["landmark_map"] = landmark_map(run, config)
        if stop.signal is not None:
            metrics["stopped_by"] = signal.Signals(stop.signal).name
        write_outputs(result, run, metrics, Path(args.out))
        if opts.mcap or opts.rerun:
            write_recordings(team_recording(result, run, args.run), opts.mcap, opts.rerun)
    summary = {
        name: round(v[mode]["ate_rmse"], 4)
        for name, v in metrics["per_robot"].items()
        if isinstance(v.get(mode), dict) and "ate_rmse" in v[mode]
    }
    print(
        dumps_json(
            {
                "mode": mode,
                "partial": metrics["partial"],
                "ate_rmse_m": summary,
                "decisions": metrics["decisions"],
                "realtime_factor": round(metrics["realtime_factor"], 1),
                "skipped": metrics["skipped"]["counts"],
                "notes": metrics["notes"]["counts"],
                "landmark_map": metrics["landmark_map"],
            },
            indent=1,
        )
    )
    return EXIT_STOPPED if metrics["partial"] else OK


def run(args: argparse.Namespace) -> int:
    return many_runs.dispatch(args, MODE, run_verb)
