"""`run_team`: one team run from its source to its outputs -- read (`datasets.open_run`), graph
(`team_graph`), solve (`team_graph.solve`), judge and write (`pipelines.report`) -- the route of
`graphloc smooth` / `online` and of the Python API (docs/api.md)."""

from __future__ import annotations

import json
import signal
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from graphloc.pipelines.team_graph.options import RunOptions
from graphloc.structured import dumps_json


@dataclass(frozen=True)
class TeamOutcome:
    """What `run_team` made: the solve (`team_graph.TeamResult`), the run it read and the
    metrics it wrote (metrics.json, docs/outputs.md)."""

    result: object
    run: object
    metrics: dict


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


def run_team(
    source,
    out,
    mode: str = "batch",
    options: RunOptions | None = None,
    stop=None,
    checkpoint=None,
    progress: bool = False,
    on_phase=None,
) -> TeamOutcome:
    """Read `source` (`open_run`), build its graph, solve it (`mode` "batch" or "online"; `options`:
    `RunOptions`, None: the defaults), evaluate and write every output into `out`. stop(): True ends
    the solve early (the outputs so far written, `partial`); checkpoint(graph, option values) -> the
    solve's on_step / on_stop hooks; on_phase(name): told "solving" and "writing" (the command
    line's Ctrl-C handling)."""
    from graphloc.datasets import open_run
    from graphloc.manifest import check_noise_params
    from graphloc.pipelines.team_graph import solve

    opts = RunOptions() if options is None else options
    values = asdict(opts)
    noise = opts.noise()
    check_noise_params(noise, "option (command line or --config)")
    cpu0 = time.process_time()
    run = open_run(source, duration=opts.duration, noise=noise, source=opts.source())
    config = opts.graph_config(run)
    graph = team_graph(run, config)
    hooks = checkpoint(graph, values) if checkpoint is not None else {}
    if on_phase is not None:
        on_phase("solving")
    result = solve(graph, mode=mode, progress=progress, stop=stop, **hooks)
    cpu = time.process_time() - cpu0
    if on_phase is not None:
        on_phase("writing")
    metrics = write_run(result, run, out, opts, config, cpu, stop, progress, source)
    return TeamOutcome(result, run, metrics)


def team_graph(run, config):
    """The graph `run_team` solves, batch and online alike: `live.builder.build_live`, the live
    team's builder fed the run's whole tables."""
    from graphloc.live.builder import build_live

    return build_live(run, config)


def write_run(
    result, run, out, opts: RunOptions, config, cpu: float, stop=None, progress=False, source=None
) -> dict:
    """Judge and write a solved run (`run_team`'s last phase, and `graphloc live`'s at its
    end): metrics with the consistency verdict (`report.evaluate`), every output of
    docs/outputs.md into `out`, the MCAP / Rerun recordings the options ask for. Returns the
    metrics (metrics.json)."""
    from graphloc.pipelines.report import evaluate, groundtruths, write_metrics, write_outputs

    values = asdict(opts)
    truth = groundtruths(run)
    metrics = evaluate(result, run, truth, stop, opts.align, cpu)
    metrics["config"] = json.loads(dumps_json(asdict(config), default=str))
    metrics["options"] = values
    metrics["landmark_map"] = landmark_map(run, config)
    signalled = getattr(stop, "signal", None)
    if signalled is not None:
        metrics["stopped_by"] = signal.Signals(signalled).name
    out = Path(out)
    write_outputs(
        result, run, metrics, out, opts.groundtruth_rate, progress, truth, stop, opts.align
    )
    recordings = [f for f in (opts.mcap, opts.rerun) if f]
    if recordings and not (stop is not None and stop()):
        from graphloc.pipelines.recording import team_recording, write_recordings

        write_recordings(team_recording(result, run, source), opts.mcap, opts.rerun)
    elif recordings:  # stopped: left out (they read the whole ground truth)
        metrics["skipped_outputs"] += recordings
    signalled = getattr(stop, "signal", None)
    if signalled is not None:  # metrics.json says who stopped the run and what is missing
        metrics["stopped_by"] = signal.Signals(signalled).name
        write_metrics(out, metrics)
    return metrics
