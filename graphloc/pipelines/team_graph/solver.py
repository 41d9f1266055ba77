"""`solve`: a `TeamGraph` through one `Session` -- batch Levenberg-Marquardt or online iSAM2
(fixed lag when `GraphConfig.lag` > 0), stoppable, with per-step latency logs."""

from __future__ import annotations

import time as _time
from dataclasses import replace

from tqdm import tqdm

from graphloc.exitcodes import SolverFailure
from graphloc.keys import decode
from graphloc.pipelines.team_graph.graph import TeamGraph
from graphloc.pipelines.team_graph.passes import STEP_LOG_COLUMNS, Pass, TeamResult, start_only
from graphloc.pipelines.team_graph.side_by_side import MAX_CHECKS, SideBySide, start_times

__all__ = ["STEP_LOG_COLUMNS", "TeamResult", "hypotheses", "solve", "warm_starts"]


def solve(
    graph: TeamGraph,
    mode: str = "batch",
    progress: bool = False,
    stop=None,
    on_step=None,
    on_stop=None,
) -> TeamResult:
    """Batch: every step added, one LM solve; online: one iSAM2 update per step (a fixed lag when
    `config.lag` > 0; a factor on a marginalized variable is left out, `TeamResult.dropped`).
    Alternative placements run side by side as hypotheses (`hypotheses`); a batch solve with
    robust kernels, max-mixtures or alternatives starts LM from that incremental pass
    (docs/design_team_graph.md, "Solving"). stop(): checked before every online step and
    between LM iterations, True ends the solve there (`partial`); on_step(i): after graph step
    i; on_stop(steps_done): when stop() ended the online loop."""
    if mode == "online":
        starts = [None, *graph.guessed_alternatives]
        times = start_times(graph.guessed_alternatives, graph.guessed_alternative_times)
        try:
            return hypotheses(graph, "online", starts, progress, stop, on_step, on_stop, times)
        except SolverFailure as exc:
            if graph.config.factorization == "QR":
                raise
            # Cholesky found an ill-conditioned system indeterminate (e.g. millimetre priors
            # beside pixels no pose explains): the solve again with QR, slower but stable
            qr = replace(graph, config=replace(graph.config, factorization="QR"))
            result = hypotheses(qr, "online", starts, progress, stop, on_step, on_stop, times)
            return replace(result, solver_note=f"QR factorization (Cholesky failed: {exc})")
    t0 = _time.perf_counter()
    starts, start_from = _batch_starts(graph, stop, progress)
    if stop is not None and stop():  # stopped before LM began: its iterate is its start
        return start_only(graph, starts[0], start_from, _time.perf_counter() - t0)
    warm = _time.perf_counter() - t0  # its wall time counts in the solve's
    passes = []
    for j, initial in enumerate(starts):
        if j and stop is not None and stop():
            break
        passes.append(Pass(graph, "batch", initial, progress, stop).run(on_step if not j else None))
    result = min(passes, key=lambda p: p.chi2)
    partial = any(p.partial for p in passes) or len(passes) < len(starts)
    wall = warm + sum(p.wall_s for p in passes)
    return replace(result, wall_s=wall, batch_start=start_from, partial=partial)


def hypotheses(
    graph: TeamGraph,
    mode: str,
    starts: list,
    progress: bool = False,
    stop=None,
    on_step=None,
    on_stop=None,
    times: list | None = None,
) -> TeamResult:
    """Online passes of `graph` from each of `starts` side by side (`side_by_side.SideBySide`,
    compared MAX_CHECKS times over the run): the best surviving pass, its causal estimates chosen
    per pose, the others' final values in `TeamResult.survivors`."""
    n = len(graph.steps)
    passes = SideBySide(graph, mode, starts, stop, stride=max(1, n // MAX_CHECKS), times=times)
    start = _time.perf_counter()
    partial = False
    for i in tqdm(range(n), desc=f"{mode} steps", disable=not progress, unit="step"):
        if stop is not None and stop():
            partial = True
            if on_stop is not None:
                on_stop(i)
            break
        passes.step(i, last=i == n - 1)
        if on_step is not None:
            on_step(i)
    wall = _time.perf_counter() - start
    return replace(passes.result(partial), wall_s=wall)


def _batch_starts(graph: TeamGraph, stop, progress: bool) -> tuple[list, str]:
    """Where a batch solve starts LM (see `solve`): ([initial values, ...] (None: the graph's
    guess), what they are)."""
    robust = any(graph.config.kernels.kernel(t).name != "none" for t in set(graph.factor_types))
    plain = [None] + [{**graph.initial, **v} for v in graph.alternatives]
    if not robust and all(d.mixture is None for d in graph.decisions) and not graph.alternatives:
        return plain, "guess (no robust kernel, no max-mixture)"
    try:
        starts = warm_starts(graph, stop, progress)
    except ValueError as exc:
        return plain, f"guess and every alternative (the incremental pass failed: {exc})"
    if stop is not None and stop():  # stopped during the pass: LM stops at once, from the guess
        return [None], "guess (stopped during the incremental pass)"
    if len(starts) > 1:
        return starts, f"incremental pass ({len(starts)} hypotheses survived it)"
    return starts, "incremental pass"


def warm_starts(graph: TeamGraph, stop=None, progress: bool = False) -> list[dict]:
    """Initial values from the online pass over `graph` (iSAM2, full smoothing; every
    alternative a hypothesis, `hypotheses`): per surviving hypothesis, best first, key ->
    Pose3 / Point3 of every variable it estimated, the graph's guess for the rest."""
    online = replace(graph, config=replace(graph.config, lag=0.0))
    starts = [None, *graph.alternatives]
    times = start_times(graph.alternatives, graph.alternative_times)
    result = hypotheses(online, "online", starts, progress, stop, times=times)
    if stop is not None and stop():  # stopped: the batch solve starts from the guess
        return [dict(graph.initial)]
    out = []
    for values in [result.values, *result.survivors]:
        start = dict(graph.initial)
        for key in graph.initial:
            if values.exists(key):
                pose = decode(key)[0] in ("x", "s")
                start[key] = values.atPose3(key) if pose else values.atPoint3(key)
        out.append(start)
    return out
