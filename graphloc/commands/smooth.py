"""`graphloc smooth RUN --out DIR`: batch smoothing (Levenberg-Marquardt over the whole factor
graph) of a team's run -- a graphloc log directory (every table: odometry, relative poses,
bearings, ranges, range-bearing, markers -> P3P candidate sets, surfaces) or an MRCLAM dataset
directory (`graphloc.datasets.open_run`, `graphloc.pipelines.team_graph`). Writes per-robot
TUM trajectories, metrics.json, decisions.csv and PNG plots (docs/outputs.md).

Options come from the command line and from `--config FILE` (TOML, the same names as the
options with '_' for '-'); the command line wins. Sensor noise options replace what the log's
sensor params state; left unset, the log's values (or graphloc's defaults) hold."""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
import tomllib
from pathlib import Path

from graphloc import many_runs
from graphloc.exitcodes import INCOMPLETE, OK
from graphloc.manifest import check_noise_params
from graphloc.pipelines.team_graph import DEFAULT_LAG

HELP = (
    "batch factor-graph smoothing of a team's run (log dir or MRCLAM dir): TUM, metrics JSON, PNGs"
)
MODE = "batch"
EXIT_STOPPED = INCOMPLETE  # SIGINT / SIGTERM: the outputs so far were written, metrics partial
# option -> (type, default, help); every one can also be set in the --config file
OPTIONS = {
    "duration": (float, None, "use only the first N seconds"),
    "keyframe_dt": (float, 0.25, "pose grid of wheel-odometry robots [s]"),
    "sync_tolerance": (
        float,
        0.02,
        "largest time offset between a measurement and its pose [s] "
        "(robots without wheel odometry)",
    ),
    "no_landmarks": (bool, False, "ignore landmark measurements"),
    "no_inter_robot": (bool, False, "ignore robot-to-robot measurements"),
    "unknown_landmarks": (
        bool,
        False,
        "cooperative SLAM: estimate landmark positions instead of using the map",
    ),
    "kernel": (
        str,
        "cauchy:2.0",
        "robust kernel NAME[:k] of landmark and inter-robot factors "
        "(huber, cauchy, tukey, gemanmcclure, dcs, none)",
    ),
    "odometry_kernel": (str, "none", "robust kernel NAME[:k] of odometry factors"),
    "candidate_kernel": (str, "cauchy:1.0", "robust kernel NAME[:k] of committed P3P candidates"),
    "bearing_sigma": (
        float,
        None,
        "bearing noise [rad] of every sensor (default: the log's, else 0.02)",
    ),
    "range_sigma": (float, None, "range noise at 0 m [m] (default: the log's, else 0.05)"),
    "range_sigma_per_m": (
        float,
        None,
        "range noise growth [m per m] (default: the log's, else 0.035)",
    ),
    "pixel_sigma": (float, None, "marker pixel noise [px] (default: the log's, else 1.0)"),
    "lag": (
        float,
        None,
        (
            "online: fixed-lag window [s], 0 = full smoothing (default: "
            f"{DEFAULT_LAG:g} s where no variable must outlive it, else 0; see "
            "docs/outputs.md)"
        ),
    ),
    "mcap": (str, None, "also write the results as an MCAP file of ROS 2 messages (Foxglove)"),
    "rerun": (str, None, "also write a Rerun recording (.rrd; needs graphloc[viz])"),
}
NOISE = ("bearing_sigma", "range_sigma", "range_sigma_per_m", "pixel_sigma")


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
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    for name, (kind, default, text) in OPTIONS.items():
        flag = "--" + name.replace("_", "-")
        if kind is bool:
            parser.add_argument(flag, action="store_true", default=None, help=text)
        else:
            parser.add_argument(flag, type=kind, default=None, help=f"{text} (default {default})")


def options(args: argparse.Namespace) -> dict:
    """Effective option values: defaults < --config file < command line."""
    values = {name: spec[1] for name, spec in OPTIONS.items()}
    if args.config is not None:
        try:
            data = tomllib.loads(args.config.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise ValueError(f"{args.config}: cannot read config: {exc}") from None
        for key, value in data.items():
            name = key.replace("-", "_")
            if name not in OPTIONS:
                raise ValueError(
                    f"{args.config}: unknown option {key!r}; known: {', '.join(OPTIONS)}"
                )
            kind = OPTIONS[name][0]
            ok = (
                isinstance(value, bool)
                if kind is bool
                else (
                    isinstance(value, (int, float)) and not isinstance(value, bool)
                    if kind is float
                    else isinstance(value, str)
                )
            )
            if not ok:
                raise ValueError(
                    f"{args.config}: option {key!r} must be a {kind.__name__}, got {value!r}"
                )
            values[name] = float(value) if kind is float else value
    for name in OPTIONS:
        given = getattr(args, name, None)
        if given is not None:
            values[name] = given
    duration = values["duration"]
    if duration is not None and not (0 < duration < float("inf")):
        raise ValueError(
            f"option --duration (or 'duration' in --config) must be > 0, got {duration}"
        )
    return values


def graph_config(values: dict):
    from graphloc.factors.robust import Kernel, KernelPolicy
    from graphloc.pipelines.team_graph import GraphConfig

    parsed = {}
    for name in ("kernel", "candidate_kernel", "odometry_kernel"):
        try:
            parsed[name] = Kernel.parse(values[name])
        except ValueError as exc:
            flag = "--" + name.replace("_", "-")
            raise ValueError(f"option {flag} (or {name!r} in --config): {exc}") from None
    kernels = KernelPolicy(
        {
            "landmark": parsed["kernel"],
            "inter_robot": parsed["kernel"],
            "candidate": parsed["candidate_kernel"],
        },
        default=parsed["odometry_kernel"],
    )
    if values["no_landmarks"] and values["no_inter_robot"]:
        raise ValueError("--no-landmarks with --no-inter-robot leaves only odometry")
    return GraphConfig(
        keyframe_dt=values["keyframe_dt"],
        sync_tolerance=values["sync_tolerance"],
        use_landmarks=not values["no_landmarks"],
        use_inter_robot=not values["no_inter_robot"],
        landmark_priors=not values["unknown_landmarks"],
        kernels=kernels,
    )


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

    values = options(args)
    config = graph_config(values)
    progress = not args.no_progress
    with StopFlag() as stop:
        noise = {k: values[k] for k in NOISE if values[k] is not None}
        check_noise_params(noise, "option (command line or --config)")
        run = open_run(args.run, duration=values["duration"], noise=noise)
        lag = values["lag"] if values["lag"] is not None else default_lag(run, config)
        if not (lag >= 0 and lag < float("inf")):
            raise ValueError(f"--lag must be finite >= 0, got {lag}")
        config = replace(config, lag=float(lag))
        graph = build_graph(run, config, progress=progress)
        hooks = checkpoint(graph, values) if checkpoint is not None else {}
        result = solve(graph, mode=mode, progress=progress, stop=stop, **hooks)
        metrics = evaluate(result, run)
        metrics["config"] = json.loads(json.dumps(asdict(config), default=str))
        metrics["options"] = values
        metrics["landmark_map"] = landmark_map(run, config)
        if stop.signal is not None:
            metrics["stopped_by"] = signal.Signals(stop.signal).name
        write_outputs(result, run, metrics, Path(args.out))
        if values["mcap"] or values["rerun"]:
            write_recordings(team_recording(result, run, args.run), values["mcap"], values["rerun"])
    summary = {
        name: round(v[mode]["ate_rmse"], 4)
        for name, v in metrics["per_robot"].items()
        if isinstance(v.get(mode), dict) and "ate_rmse" in v[mode]
    }
    print(
        json.dumps(
            {
                "mode": mode,
                "partial": metrics["partial"],
                "ate_rmse_m": summary,
                "decisions": metrics["decisions"],
                "realtime_factor": round(metrics["realtime_factor"], 1),
                "skipped": metrics["skipped"]["counts"],
                "landmark_map": metrics["landmark_map"],
            },
            indent=1,
        )
    )
    print(f"outputs in {args.out}")
    return EXIT_STOPPED if metrics["partial"] else OK


def run(args: argparse.Namespace) -> int:
    return many_runs.dispatch(args, MODE, run_verb)
