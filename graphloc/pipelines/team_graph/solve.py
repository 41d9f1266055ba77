"""`solve`: a `TeamGraph` through one `Session` -- batch Levenberg-Marquardt or online iSAM2
(fixed lag when `GraphConfig.lag` > 0), stoppable, with per-step latency logs."""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field, replace

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.factors.robust import downweighted
from graphloc.keys import decode, decode_many, pose_key
from graphloc.pipelines.team_graph.config import ANCHOR_BASE
from graphloc.pipelines.team_graph.graph import TeamGraph, factor_keys
from graphloc.pipelines.team_graph.motion import compose_steps
from graphloc.pipelines.team_graph.rows import grid_rows, pose_grids, pose_row, values_poses
from graphloc.session import Session


@dataclass(frozen=True)
class TeamResult:
    """estimate[r]: (K_r,7) x y z qx qy qz qw per pose (NaN where left out); causal[r]: the
    online estimate of each pose right after its own step (NaN in batch); latencies (steps,);
    step_log: one row per session step (step index in graph.steps, time, latency [s], CPU [s],
    factors added, variables the solver holds); dropped: factors not added because they touch
    a variable the fixed lag has marginalized, by type; partial: the solve stopped early
    (`stop`) after `steps_done` of the graph's steps; decisions: the graph's, with the sets of
    the max-mixture route chosen at the final estimate (`choose_mixtures`)."""

    mode: str
    node_times: list
    estimate: list
    causal: list
    dead_reckoning: list
    latencies: np.ndarray
    wall_s: float
    graph: TeamGraph
    downweighted: dict
    landmarks: (
        dict  # landmark id -> estimated position (3,) of landmarks that are one variable (SLAM)
    )
    step_log: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    dropped: dict = field(default_factory=dict)
    partial: bool = False
    steps_done: int = 0
    lag: float | None = None
    decisions: list = field(default_factory=list)  # graph.decisions, max-mixtures chosen
    values: object = None  # gtsam.Values: the final estimate of every variable
    error: float = float("nan")  # the error of the factors the solve added, at the final estimate
    batch_start: str = ""  # batch: where LM started (`solve`)


RELEASE_UPDATES = 5  # extra iSAM2 updates when held factors enter (a robot placed late)
STEP_LOG_COLUMNS = ("step", "time", "latency_s", "cpu_s", "factors", "variables")


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
    A batch solve of a graph with robust kernels or max-mixtures starts LM from a causal
    incremental pass (full smoothing, `warm_start`), not from the graph's dead-reckoning guess:
    there, metres off, robust kernels give up on measurements that are right (a Cauchy weight
    falls with the residual) and LM settles in a minimum of higher error; a max-mixture is
    chosen at its linearization point, so a camera without odometry can sit in the false
    candidate's basin. The incremental pass meets each measurement near its own pose and
    chooses each set near its own frame, as the online solve does. Where iSAM2 cannot solve
    that pass (an indeterminate step LM's damping gets through), LM starts from the guess;
    `TeamResult.batch_start` says which.
    A batch solve also starts from each of `graph.alternatives` (the candidates of a marker
    pixel stream's first set, or of a resected robot's first sets, `team_graph.formation`)
    and keeps the estimate of least error: the solve, not one frame, chooses among the
    placements P3P leaves open. Online, a robot placed by a guess (the tracker never decided
    its stream, or resection placed it) is run as one hypothesis per such start
    (`graph.guessed_alternatives`), side by side over the same steps: the final estimate is
    the hypothesis of least error at the end, and each pose's causal estimate comes from the
    hypothesis of least error at the step that pose entered -- a choice made with the data up
    to that step only."""
    t0 = _time.perf_counter()
    initial, start_from = None, ""
    if mode == "batch":
        initial, start_from = _batch_start(graph, stop, progress)
        if stop is not None and stop():  # stopped before LM began: its iterate is its start
            return _start_only(graph, initial, start_from, _time.perf_counter() - t0)
    warm = _time.perf_counter() - t0  # its wall time counts in the solve's
    variants = graph.alternatives if mode == "batch" else graph.guessed_alternatives
    traces: list = [{} if variants and mode == "online" else None]
    result = _solve(graph, mode, progress, stop, on_step, on_stop, initial, traces[0])
    result = replace(result, batch_start=start_from)
    if result.partial or not variants:
        return replace(result, wall_s=result.wall_s + warm)
    passes, wall = [result], result.wall_s + warm
    for variant in variants:
        if stop is not None and stop():
            break
        trace = {} if mode == "online" else None
        start = {**(initial or graph.initial), **variant}
        other = _solve(graph, mode, progress, stop, None, None, start, trace)
        wall += other.wall_s
        if not other.partial:
            passes.append(other)
            traces.append(trace)
    best = min(range(len(passes)), key=lambda j: passes[j].error)
    result = passes[best]
    if mode == "online":
        result = replace(result, causal=_causal_of_least_error(passes, traces))
    return replace(result, wall_s=wall)


def _causal_of_least_error(passes: list, traces: list) -> list:
    """Per pose, the causal estimate of the online pass whose error was least at the step
    that pose entered (`traces[j]`: step -> error, robot -> {node: step})."""
    causal = [rows.copy() for rows in passes[0].causal]
    for r, rows in enumerate(causal):
        for k, i in traces[0]["entered"].get(r, {}).items():
            j = min(range(len(passes)), key=lambda j: traces[j]["error"].get(i, np.inf))
            rows[k] = passes[j].causal[r][k]
    return causal


def _solve(
    graph: TeamGraph, mode, progress, stop, on_step, on_stop, initial, trace=None
) -> TeamResult:
    """One solve of `graph` (see `solve`) from `initial` (key -> value; None: graph.initial).
    trace (online, a dict): filled with the graph error after each step ("error": step ->
    error) and the step each pose entered ("entered": robot -> {node: step})."""
    if trace is not None:
        trace.update(error={}, entered={})
    cfg = graph.config
    lag = float(cfg.lag or 0.0) if mode == "online" else 0.0
    session = Session(
        replace(
            cfg.session_config(mode, graph.precision, camera_graph(graph)),
            lag=lag,
        ),
        progress=progress and mode == "batch",
        stop=stop,
    )
    # per robot, each pose's estimate right after its step, [R | t] (preallocated: no growth)
    causal = [np.full((len(t), 3, 4), np.nan) for t in graph.node_times]
    start = _time.perf_counter()
    added: set = set()
    held: list = []  # online: factors on robots not yet anchored
    latest: dict = {}
    types: list = []  # factor types in the order the session holds them
    dropped: dict = {}
    log: list = []
    partial, done = False, 0
    # online: until the last robot is anchored, factors on robots not yet anchored wait
    hold_until = max(graph.anchored_from.values(), default=-np.inf)
    gone = session.marginalized_keys  # grows as the fixed lag marginalizes
    if mode != "online":
        hold_until = -np.inf
    for i, (t, group) in enumerate(
        tqdm(graph.steps, desc=f"{mode} steps", disable=not progress, unit="step")
    ):
        if mode == "online" and stop is not None and stop():
            partial = True
            if on_stop is not None:
                on_stop(done)
            break
        done = i + 1
        values = gtsam.Values()
        factors = []
        waiting, held = held + group, []
        released = 0  # factors that waited for their robot's placement and enter now
        new_poses = []  # (key, robot, index) of the poses this step adds
        for n, (f, kind) in enumerate(waiting):
            keys = factor_keys(f)
            if t < hold_until and any(_held(graph, key, t) for key in keys):
                held.append((f, kind))
                continue
            if lag and not gone.isdisjoint(keys):
                dropped[kind] = dropped.get(kind, 0) + 1
                continue
            for key in keys:
                if key not in added:
                    decoded = decode(key)
                    values.insert(key, _predict(graph, key, decoded, latest, initial))
                    added.add(key)
                    if decoded[0] == "x":
                        new_poses.append((key, *decoded[1:]))
            factors.append(f)
            types.append(kind)
            released += n < len(waiting) - len(group)
        if factors:
            step = session.add(factors, values, time=t)
            latency, cpu = step.latency_s, step.cpu_s
            if mode == "online" and released:
                # a robot placed late enters with its whole past at once: iterate iSAM2 on it
                for _ in range(RELEASE_UPDATES):
                    extra = session.add([], gtsam.Values(), time=t)
                    latency, cpu = latency + extra.latency_s, cpu + extra.cpu_s
            log.append((i, t, latency, cpu, len(factors), session.live_variables()))
        if factors and mode == "online":
            est = session.estimate([key for key, _, _ in new_poses])
            if trace is not None:
                trace["error"][i] = session.error()
            for key, r, k in new_poses:
                p = est.atPose3(key)
                causal[r][k] = p.matrix()[:3]
                if trace is not None:
                    trace["entered"].setdefault(r, {})[k] = i
                if k >= latest.get(r, (-1, None))[0]:
                    latest[r] = (k, p)
        if on_step is not None:
            on_step(i)
    final = session.estimate()
    decisions = choose_mixtures(graph.decisions, final)
    partial = partial or session.stopped
    wall = _time.perf_counter() - start
    estimate = [grid_rows(g) for g in pose_grids(graph.node_times, *values_poses(final))]
    dead = _guess_rows(graph, graph.initial)
    down = {}
    types = np.array(types)
    for ftype in ("odometry", "landmark", "inter_robot", "candidate"):
        if partial:  # a stopped solve: returned promptly, its kernels' weights not evaluated
            break
        if cfg.kernels.kernel(ftype).name == "none" or not (types == ftype).any():
            continue
        rep = downweighted(
            session.graph, final, cfg.downweight_threshold, indices=np.flatnonzero(types == ftype)
        )
        down[ftype] = {
            "robust_factors": rep.n_robust,
            "downweighted": rep.n_downweighted,
            "threshold": cfg.downweight_threshold,
        }
    keys = final.keys()
    kind, lid, _ = decode_many(keys)
    landmarks = {
        int(lid[j]): np.asarray(final.atPoint3(keys[j]))
        for j in np.flatnonzero((kind == "l") & (lid < ANCHOR_BASE))
    }
    step_log = np.array(log, dtype=float).reshape(-1, len(STEP_LOG_COLUMNS))
    return TeamResult(
        mode,
        graph.node_times,
        estimate,
        [grid_rows(c) for c in causal],
        dead,
        session.latencies(),
        wall,
        graph,
        down,
        landmarks,
        step_log,
        dropped,
        partial,
        done,
        lag if mode == "online" else None,
        decisions,
        final,
        session.error(final),
    )


def _guess_rows(graph: TeamGraph, values: dict) -> list:
    """Per robot, (K_r,7) rows of the poses `values` (key -> Pose3) holds, NaN elsewhere."""
    guessed = [
        (r, k, values[key].matrix())
        for r, times in enumerate(graph.node_times)
        for k in range(len(times))
        if (key := pose_key(r, k)) in values
    ]
    robot, index, m = zip(*guessed) if guessed else ((), (), np.zeros((0, 4, 4)))
    return [grid_rows(g) for g in pose_grids(graph.node_times, robot, index, np.array(m))]


def _start_only(graph: TeamGraph, initial: dict | None, start_from: str, wall: float):
    """A batch solve stopped before LM began (a signal during its incremental pass): partial,
    its estimate the LM iterate it would have started from, `initial` (None: the graph's
    guess); no session is built, so the stop returns at once."""
    start = graph.initial if initial is None else initial
    return TeamResult(
        "batch",
        graph.node_times,
        _guess_rows(graph, start),
        [np.full((len(t), 7), np.nan) for t in graph.node_times],
        _guess_rows(graph, graph.initial),
        np.zeros(0),
        wall,
        graph,
        {},
        {},
        partial=True,
        decisions=list(graph.decisions),
        batch_start=f"{start_from}; stopped before Levenberg-Marquardt",
    )


def _held(graph: TeamGraph, key: int, t: float) -> bool:
    kind, r, _ = decode(key)
    return kind == "x" and graph.anchored_from.get(r, np.inf) > t


def camera_graph(graph: TeamGraph) -> bool:
    """The graph holds feature tracks or max-mixtures (`GraphConfig.session_config`)."""
    return graph.counts.get("feature_tracks", 0) > 0 or any(
        d.mixture is not None for d in graph.decisions
    )


def _batch_start(graph: TeamGraph, stop, progress: bool) -> tuple[dict | None, str]:
    """Where a batch solve starts LM (see `solve`): (initial values or None for the graph's
    guess, what they are)."""
    robust = any(graph.config.kernels.kernel(t).name != "none" for t in set(graph.factor_types))
    if not robust and all(d.mixture is None for d in graph.decisions):
        return None, "guess (no robust kernel, no max-mixture)"
    try:
        initial = warm_start(graph, stop, progress)
    except ValueError as exc:
        return None, f"guess (the incremental pass failed: {exc})"
    if stop is not None and stop():  # stopped during the pass: LM stops at once, from the guess
        return None, "guess (stopped during the incremental pass)"
    return initial, "incremental pass"


def warm_start(graph: TeamGraph, stop=None, progress: bool = False) -> dict:
    """Initial values from an online pass over `graph` (iSAM2, full smoothing): key -> Pose3 /
    Point3 of every variable it estimated, the graph's guess for the rest."""
    online = replace(graph, config=replace(graph.config, lag=0.0))
    values = solve(online, mode="online", progress=progress, stop=stop).values
    out = dict(graph.initial)
    for key in graph.initial:
        if values.exists(key):
            out[key] = values.atPose3(key) if decode(key)[0] == "x" else values.atPoint3(key)
    return out


def _predict(graph: TeamGraph, key: int, decoded: tuple, latest: dict, initial: dict | None):
    """Initial value of a new variable: a landmark's guess; a pose from its robot's latest
    estimate composed with the odometry since -- or, where it sees a target of the
    max-mixture route that its own odometry predicts worse than the target's does, resected
    from the target (`_resected`) --, else the graph's initial guess."""
    kind, r, k = decoded  # decode(key)
    if kind != "x":
        return (graph.initial if initial is None else initial)[key]
    if r in latest and latest[r][0] < k:
        k0, pose = latest[r]
        linked = key in graph.links  # only a resection needs the prediction's covariance
        rel, cov = compose_steps(graph.step_rel[r], k0, k, graph.config, covariance=linked)
        if all(s is not None for s in graph.step_rel[r][k0 + 1 : k + 1]):
            predicted = pose.compose(rel)
            if not linked:
                return predicted
            return _resected(graph, key, latest, predicted, np.trace(cov[3:, 3:])) or predicted
    return (graph.initial if initial is None else initial)[key]


def _resected(graph: TeamGraph, key: int, latest: dict, predicted, spread: float):
    """The observer pose `key` from its target's predicted pose through the candidate whose
    rotation is nearest the observer's own prediction (seed 003: a camera without odometry
    re-found from a teammate that stood still; from its previous pose alone, centimetres off,
    the solve can settle in the false candidate's basin), when the target's prediction is
    tighter than the observer's (`spread`: trace of its translation covariance); else None."""
    link = graph.links.get(key)
    if link is None:
        return None
    tkey, relative = link
    _, ti, kt = decode(tkey)
    if ti not in latest or latest[ti][0] > kt:
        return None
    k0, target = latest[ti]
    if k0 < kt:
        step, cov = compose_steps(graph.step_rel[ti], k0, kt, graph.config)
        if np.trace(cov[3:, 3:]) >= spread:
            return None
        target = target.compose(step)
    poses = [target.compose(gtsam.Pose3(T).inverse()) for T in relative]
    angles = [
        np.linalg.norm(gtsam.Rot3.Logmap(predicted.rotation().between(p.rotation()))) for p in poses
    ]
    return poses[int(np.argmin(angles))]


def choose_mixtures(decisions: list, estimate: gtsam.Values) -> list:
    """The decisions with every max-mixture set chosen at `estimate`: the component the factor
    is linearized at (`MaxMixture.active`), its posterior among the components
    (exp(-component error) normalized) and the observer's estimated pose."""
    out = []
    for d in decisions:
        if d.mixture is None or not all(estimate.exists(k) for k in d.mixture.keys):
            out.append(d)
            continue
        errors = d.mixture.component_errors(estimate)
        p = np.exp(-(errors - errors.min()))
        p /= p.sum()
        j = int(np.argmin(errors))
        observer = d.mixture.components[j][0].keys()[0]
        out.append(
            replace(
                d,
                committed=j,
                probability=float(p[j]),
                probabilities=p,
                pose=pose_row(estimate.atPose3(observer)),
                same_pose=[j],
            )
        )
    return out
