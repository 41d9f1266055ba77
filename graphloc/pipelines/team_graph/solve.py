"""`solve`: a `TeamGraph` through one `Session` -- batch Levenberg-Marquardt or online iSAM2
(fixed lag when `GraphConfig.lag` > 0), stoppable, with per-step latency logs."""

from __future__ import annotations

import time as _time
from dataclasses import replace

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.exitcodes import SolverFailure
from graphloc.keys import decode
from graphloc.pipelines.team_graph.graph import TeamGraph
from graphloc.pipelines.team_graph.passes import STEP_LOG_COLUMNS, Pass, TeamResult, start_only

__all__ = ["STEP_LOG_COLUMNS", "TeamResult", "hypotheses", "solve", "warm_start", "warm_starts"]


PRUNE_CHI2 = 50.0  # a hypothesis whose chi-square exceeds the least by this much is dropped
SETTLE_UPDATES = 5  # ... after at most this many more iSAM2 iterations of both
SAME_ESTIMATE = (0.01, 0.01)  # (m, rad): hypotheses whose latest poses agree this well are one
EARLY_CHECKS = 20  # hypotheses are compared after each of the first steps
MAX_CHECKS = 200  # hypotheses are compared at most this many times over a run (and at its end)


def solve(
    graph: TeamGraph,
    mode: str = "batch",
    progress: bool = False,
    stop=None,
    on_step=None,
    on_stop=None,
) -> TeamResult:
    """Batch: every step added, one LM solve. Online: one iSAM2 update per step (with
    `config.lag` > 0 a fixed-lag smoother, `Session`); a new pose is predicted from its robot's
    latest estimate and odometry; robots enter at their first anchor; a factor touching a
    marginalized variable is left out and counted (`TeamResult.dropped`). stop(): checked
    before every online step and between LM iterations, True ends the solve there (the result
    is marked partial: online, the estimate after the last finished step; batch, the LM
    iterate).
    on_step(i): called after graph step i was consumed; on_stop(steps_done): when stop()
    ended the online loop.

    Alternatives (`graph.alternatives`: the candidates of a marker pixel stream's first set,
    or of a resected robot's first sets, `team_graph.formation`; the online solve runs those of
    robots a guess placed, `graph.guessed_alternatives`) are hypotheses run side by side over
    the same steps (`hypotheses`), each an online pass from its own start. They are compared
    by their posterior: the chi-square of every factor so far without the robust kernels
    (`factors.robust.residuals`) -- a placement that explains its measurements by down-
    weighting them as outliers does not win on the kernel's saturated error --, and a
    hypothesis whose chi-square exceeds the least by `PRUNE_CHI2` is dropped as the evidence
    arrives (an alternative no earlier than the step of the node it was placed at,
    `judged_from`: seed 000's climber placed by a later snapshot's P3P candidate starts its
    earlier poses at that snapshot's position), so one pass carries the rest of the run; an
    iSAM2 update is one Gauss-Newton step, so before one is dropped both it and the best get a
    few more iterations (a pass far from its minimum is no evidence against it), and
    hypotheses that converged to one estimate are one.
    The online estimate
    is the surviving hypothesis of least chi-square at the end; each pose's causal estimate
    comes from the hypothesis of least chi-square when that pose entered (a choice made with
    the data up to that step only).
    A batch solve of a graph with robust kernels, max-mixtures or alternatives starts LM from
    that incremental pass (full smoothing; from each surviving hypothesis, the least chi-square
    kept), not from the graph's dead-reckoning guess: there, metres off, robust kernels give
    up on measurements that are right (a Cauchy weight falls with the residual) and LM settles
    in a minimum of higher error; a max-mixture is chosen at its linearization point, so a
    camera without odometry can sit in the false candidate's basin. The incremental pass meets
    each measurement near its own pose and chooses each set near its own frame, as the online
    solve does. Where iSAM2 cannot solve that pass (an indeterminate step LM's damping gets
    through), LM starts from the guess and from every alternative; `TeamResult.batch_start`
    says which."""
    if mode == "online":
        starts = [None, *graph.guessed_alternatives]
        judged = judged_from(graph, graph.guessed_alternatives, graph.guessed_alternative_times)
        try:
            return hypotheses(graph, "online", starts, progress, stop, on_step, on_stop, judged)
        except SolverFailure as exc:
            if graph.config.factorization == "QR":
                raise
            # Cholesky found an ill-conditioned system indeterminate (e.g. millimetre priors
            # beside pixels no pose explains): the solve again with QR, slower but stable
            qr = replace(graph, config=replace(graph.config, factorization="QR"))
            result = hypotheses(qr, "online", starts, progress, stop, on_step, on_stop, judged)
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
    judged: list | None = None,
) -> TeamResult:
    """Online passes of `graph` from each of `starts` (key -> value over the graph's guess;
    None: the guess) side by side, step by step, compared and pruned by chi-square (`solve`).
    judged: per start, the first step at which it may be dropped (`judged_from`; None: 0 for
    all): a resected robot's alternative from a later snapshot's P3P candidate starts its
    earlier poses at that snapshot's position (seed 000, Sec. IV: the climber moves between
    snapshots), so the steps before its own snapshot are no evidence against it.
    Returns the best surviving pass, its causal estimates chosen per pose, and the others
    that survived in `TeamResult.survivors` (their final values)."""
    passes = [
        Pass(graph, mode, None if s is None else {**graph.initial, **s}, False, stop)
        for s in starts
    ]
    alive = list(range(len(passes)))
    judged = [0] * len(passes) if judged is None else judged
    chi2 = np.zeros(len(passes))
    best_at: list = []  # step -> index of the best pass then
    stride = max(1, len(graph.steps) // MAX_CHECKS)
    start = _time.perf_counter()
    partial = False
    for i in tqdm(range(len(graph.steps)), desc=f"{mode} steps", disable=not progress, unit="step"):
        if stop is not None and stop():
            partial = True
            if on_stop is not None:
                on_stop(i)
            break
        for j in list(alive):
            try:
                passes[j].step(i)
            except ValueError:  # iSAM2 cannot solve this hypothesis: it is dropped
                if len(alive) == 1:
                    raise
                alive.remove(j)
        if len(alive) > 1:
            alive = _distinct(passes, alive)
        if len(alive) > 1 and (i % stride == 0 or i < EARLY_CHECKS or i == len(graph.steps) - 1):
            alive = _prune(passes, alive, chi2, {j for j in alive if judged[j] > i})
        best_at.append(min(alive, key=lambda j: chi2[j]))
        if on_step is not None:
            on_step(i)
    wall = _time.perf_counter() - start
    results = {j: passes[j].result() for j in alive}
    best = min(alive, key=lambda j: results[j].chi2)
    result = results[best]
    if len(passes) > 1:  # each pose's causal estimate from the pass best when it entered
        causal = [rows.copy() for rows in result.causal]
        for r, rows in enumerate(causal):
            for k in range(len(rows)):
                i = passes[0].entered.get((r, k))
                if i is not None and i < len(best_at):
                    rows[k] = passes[best_at[i]].causal_row(r, k)
        result = replace(result, causal=causal)
    return replace(
        result,
        wall_s=wall,
        partial=partial or result.partial,
        survivors=[results[j].values for j in alive if j != best],
        hypotheses=len(passes),
    )


def _distinct(passes: list, alive: list) -> list:
    """The hypotheses that are not the same estimate as an earlier one: every robot's latest
    pose within SAME_ESTIMATE (m, rad) of it (they converged to one basin)."""
    out = []
    for j in alive:
        mine = passes[j].latest
        if not any(_same(mine, passes[i].latest) for i in out):
            out.append(j)
    return out


def _same(a: dict, b: dict) -> bool:
    if a.keys() != b.keys():
        return False
    for r, (k, pose) in a.items():
        kb, other = b[r]
        if k != kb:
            return False
        d = pose.between(other)
        if np.linalg.norm(d.translation()) > SAME_ESTIMATE[0]:
            return False
        if np.linalg.norm(gtsam.Rot3.Logmap(d.rotation())) > SAME_ESTIMATE[1]:
            return False
    return True


def _prune(passes: list, alive: list, chi2: np.ndarray, unjudged: set = frozenset()) -> list:
    """Hypotheses compared by chi-square (`solve`); one more than PRUNE_CHI2 behind the best is
    first given up to SETTLE_UPDATES more iSAM2 iterations, as is the best (an update takes one
    Gauss-Newton step, and a pass far from its minimum is no evidence against it), and dropped
    if it is still behind; those in `unjudged` are kept whatever their chi-square. Updates
    `chi2` of the passes compared."""
    for j in alive:
        chi2[j] = passes[j].current_chi2()[0]
    best = min(alive, key=lambda j: chi2[j])
    behind = [j for j in alive if chi2[j] > chi2[best] + PRUNE_CHI2 and j not in unjudged]
    if not behind:
        return alive
    for j in [best, *behind]:
        try:
            chi2[j] = passes[j].settle(SETTLE_UPDATES)
        except ValueError:  # iSAM2 cannot iterate this hypothesis: it is dropped
            chi2[j] = np.inf
    best = min(alive, key=lambda j: chi2[j])
    kept = [j for j in alive if chi2[j] <= chi2[best] + PRUNE_CHI2 or j in unjudged]
    if not kept:
        raise ValueError("no hypothesis can be solved")
    return kept


def judged_from(graph: TeamGraph, alternatives: list, times: list) -> list | None:
    """Per hypothesis (the guess, then one per alternative of `alternatives`, placed at node
    time `times[j]`), the first step at which `hypotheses` may drop it: the step of its own
    node (0 for the guess); None where the times do not match the alternatives (a graph built
    without them: every step judges)."""
    if len(times) != len(alternatives):
        return None
    step_times = np.array([t for t, _ in graph.steps])
    return [0] + [int(np.searchsorted(step_times, t - 1e-9)) for t in times]


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
    judged = judged_from(graph, graph.alternatives, graph.alternative_times)
    result = hypotheses(online, "online", starts, progress, stop, judged=judged)
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


def warm_start(graph: TeamGraph, stop=None, progress: bool = False) -> dict:
    """The best of `warm_starts`."""
    return warm_starts(graph, stop, progress)[0]
