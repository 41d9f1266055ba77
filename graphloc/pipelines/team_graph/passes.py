"""`Pass`: one solve of a `TeamGraph` through one `Session`, step by step -- batch
(Levenberg-Marquardt over every step added) or online (one iSAM2 update per step, a fixed lag
when `GraphConfig.lag` > 0) -- and what it gives, `TeamResult`. `solve` runs one pass, or
several side by side (`solver.hypotheses`)."""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field, replace

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.factors.robust import GaussianChi2, residuals
from graphloc.keys import decode, decode_many, pose_key
from graphloc.pipelines.team_graph.config import ANCHOR_BASE
from graphloc.pipelines.team_graph.graph import TeamGraph, factor_keys
from graphloc.pipelines.team_graph.predict import on_body, predict
from graphloc.pipelines.team_graph.rows import (
    grid_rows,
    grids_rows,
    pose_grids,
    pose_row,
    values_poses,
)
from graphloc.pipelines.team_graph.verdict import factor_statistics, robot_statistics
from graphloc.session import Session


@dataclass(frozen=True)
class TeamResult:
    """What a solve gives: per robot the estimate (K,7 x y z qx qy qz qw, NaN where left out),
    causal (online: each pose right after its step) and dead-reckoning rows; the step log
    (STEP_LOG_COLUMNS); factors `dropped` by the fixed lag; `partial` after `steps_done` steps; the
    decisions with max-mixtures chosen; the final values, chi-square and statistics."""

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
    factor_stats: dict = field(default_factory=dict)  # type -> `factor_statistics` row
    robot_stats: dict = field(default_factory=dict)  # robot -> type -> row (`robot_statistics`)
    chi2: float = float("nan")  # the chi-square of every factor at the estimate, no kernels
    survivors: list = field(default_factory=list)  # other hypotheses' final values (`hypotheses`)
    hypotheses: int = 1  # hypotheses run side by side (alternative placements)
    solver_note: str = ""  # how the solver departed from its settings, and why (`solve`)


RELEASE_UPDATES = 5  # extra iSAM2 updates when held factors enter (a robot placed late)
STEP_LOG_COLUMNS = ("step", "time", "latency_s", "cpu_s", "factors", "variables")


class Pass:
    """One solve of `graph` from `initial` (key -> value; None: graph.initial), step by step:
    `step(i)` adds graph step i (online: one iSAM2 update), `result()` the TeamResult (batch:
    LM over everything added)."""

    def __init__(self, graph: TeamGraph, mode: str, initial, progress: bool, stop):
        self.graph, self.mode, self.initial, self.stop = graph, mode, initial, stop
        cfg = graph.config
        self.lag = float(cfg.lag or 0.0) if mode == "online" else 0.0
        self.session = Session(
            replace(cfg.session_config(mode, graph.precision, graph.camera), lag=self.lag),
            progress=progress and mode == "batch",
            stop=stop,
        )
        self.progress = progress
        # per robot, each pose's estimate right after its step, [R | t] (preallocated)
        self.causal = [np.full((len(t), 3, 4), np.nan) for t in graph.node_times]
        self.added: set = set()
        self.held: list = []  # online: factors on robots not yet anchored
        self.latest: dict = {}
        self.types: list = []  # factor types in the order the session holds them
        self.owners: list = []  # ... and the robot each belongs to (`_owner`)
        self.dropped: dict = {}
        self.log: list = []
        self.entered: dict = {}  # (robot, node) -> the step its pose entered
        self.done = 0
        self.wall = 0.0
        self.chi2 = GaussianChi2()  # the session's factors without their kernels
        # online: until the last robot is anchored, factors on robots not yet anchored wait
        self.hold_until = (
            max(graph.anchored_from.values(), default=-np.inf) if mode == "online" else -np.inf
        )

    def run(self, on_step=None) -> TeamResult:
        """Every step (online: stoppable between steps), then the result."""
        steps = self.graph.steps
        for i in tqdm(
            range(len(steps)), desc=f"{self.mode} steps", disable=not self.progress, unit="step"
        ):
            if self.mode == "online" and self.stop is not None and self.stop():
                break
            self.step(i)
            if on_step is not None:
                on_step(i)
        return self.result()

    def step(self, i: int) -> None:
        """Add graph step i."""
        t0 = _time.perf_counter()
        graph, session = self.graph, self.session
        t, group = graph.steps[i]
        self.done = i + 1
        values = gtsam.Values()
        factors = []
        waiting, self.held = self.held + group, []
        released = 0  # factors that waited for their robot's placement and enter now
        new_poses = []  # (key, robot, index) of the poses this step adds
        gone = session.marginalized_keys  # grows as the fixed lag marginalizes
        for n, (f, kind) in enumerate(waiting):
            keys = factor_keys(f)
            if t < self.hold_until and any(_held(graph, key, t) for key in keys):
                self.held.append((f, kind))
                continue
            if self.lag and not gone.isdisjoint(keys):
                self.dropped[kind] = self.dropped.get(kind, 0) + 1
                continue
            for key in keys:
                if key not in self.added:
                    decoded = decode(key)
                    on_pose = key in graph.frame_points or key in graph.sensor_poses
                    if self.mode == "online" and on_pose:
                        value = on_body(graph, key, values, session, self.added)
                    else:
                        value = predict(graph, key, decoded, self.latest, self.initial)
                    values.insert(key, value)
                    self.added.add(key)
                    if decoded[0] == "x":
                        new_poses.append((key, *decoded[1:]))
            factors.append(f)
            self.types.append(kind)
            self.owners.append(_owner(keys))
            released += n < len(waiting) - len(group)
        if factors:
            step = session.add(factors, values, time=t)
            self.chi2.add(factors)
            latency, cpu = step.latency_s, step.cpu_s
            if self.mode == "online" and released:
                # a robot placed late enters with its whole past at once: iterate iSAM2 on it
                for _ in range(RELEASE_UPDATES):
                    extra = session.add([], gtsam.Values(), time=t)
                    latency, cpu = latency + extra.latency_s, cpu + extra.cpu_s
            self.log.append((i, t, latency, cpu, len(factors), session.live_variables()))
        if factors and self.mode == "online":
            est = session.estimate([key for key, _, _ in new_poses])
            for key, r, k in new_poses:
                if k >= len(self.causal[r]):  # a graph that grows (`graphloc.live`)
                    grown = max(len(graph.node_times[r]), 2 * len(self.causal[r]))
                    self.causal[r] = _fit(self.causal[r], grown)
                p = est.atPose3(key)
                self.causal[r][k] = p.matrix()[:3]
                self.entered[(r, k)] = i
                if k >= self.latest.get(r, (-1, None))[0]:
                    self.latest[r] = (k, p)
        self.wall += _time.perf_counter() - t0

    def current_chi2(self) -> tuple[float, int]:
        """The chi-square of every factor added so far at the current estimate, without the
        robust kernels (`factors.robust.residuals`), and their residual dimension."""
        t0 = _time.perf_counter()
        chi2 = self.chi2(self.session.estimate())
        self.wall += _time.perf_counter() - t0
        return chi2, self.chi2.dim

    def settle(self, updates: int) -> float:
        """Up to `updates` more iSAM2 iterations (online, `Session.iterate`), stopping when the
        chi-square falls by less than 1 %; returns the chi-square after them."""
        chi2 = self.current_chi2()[0]
        for _ in range(updates if self.mode == "online" and self.session.steps else 0):
            self.wall += self.session.iterate()
            new = self.current_chi2()[0]
            settled = new > 0.99 * chi2
            chi2 = new
            if settled:
                break
        return chi2

    def causal_row(self, r: int, k: int) -> np.ndarray:
        return grid_rows(self.causal[r][k : k + 1])[0]

    def result(self) -> TeamResult:
        graph, session, cfg = self.graph, self.session, self.graph.config
        t0 = _time.perf_counter()
        final = session.estimate()
        self.wall += _time.perf_counter() - t0
        decisions = choose_mixtures(graph.decisions, final)
        self.causal = [_fit(c, len(t)) for c, t in zip(self.causal, graph.node_times)]
        partial = self.done < len(graph.steps) or session.stopped
        estimate = grids_rows(pose_grids(graph.node_times, *values_poses(final)))
        dead = guess_rows(graph, graph.initial)
        if partial:  # a stopped solve returns promptly: its residuals are not judged
            stats, by_robot, chi2 = {}, {}, float("nan")
        else:
            res = residuals(session.graph, final)
            types, owners = np.array(self.types), np.array(self.owners, dtype=int)
            stats = factor_statistics(res, types, cfg.downweight_threshold)
            names = [robot.name for robot in graph.run.robots]
            by_robot = robot_statistics(res, types, owners, names, cfg.downweight_threshold)
            chi2 = float(res.chi2.sum())
        down = {
            kind: {
                "robust_factors": row["robust"],
                "downweighted": row["downweighted"],
                "threshold": cfg.downweight_threshold,
            }
            for kind, row in stats.items()
            if row["robust"]
        }
        keys = final.keys()
        kind, lid, _ = decode_many(keys)
        landmarks = {
            int(lid[j]): np.asarray(final.atPoint3(keys[j]))
            for j in np.flatnonzero((kind == "l") & (lid < ANCHOR_BASE))
        }
        step_log = np.array(self.log, dtype=float).reshape(-1, len(STEP_LOG_COLUMNS))
        return TeamResult(
            self.mode,
            graph.node_times,
            estimate,
            grids_rows(self.causal),
            dead,
            session.latencies(),
            self.wall,
            graph,
            down,
            landmarks,
            step_log,
            self.dropped,
            partial,
            self.done,
            self.lag if self.mode == "online" else None,
            decisions,
            final,
            session.error(final),
            factor_stats=stats,
            robot_stats=by_robot,
            chi2=chi2,
        )


def _fit(grid: np.ndarray, n: int) -> np.ndarray:
    """A (K,3,4) grid of causal estimates cut or padded with NaN rows to n rows."""
    if len(grid) >= n:
        return grid[:n]
    return np.concatenate([grid, np.full((n - len(grid), 3, 4), np.nan)])


def _held(graph: TeamGraph, key: int, t: float) -> bool:
    kind, r, _ = decode(key)
    return kind in ("x", "s") and graph.anchored_from.get(r, np.inf) > t


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


def _owner(keys) -> int:
    """The robot a factor belongs to: its first pose's (a body or a sensor pose), else its
    first marker point's; -1."""
    for kinds in (("x", "s"), ("k",)):  # keys decoded up to the first that answers
        robot = next((d[1] for d in map(decode, keys) if d[0] in kinds), None)
        if robot is not None:
            return int(robot)
    return -1


def guess_rows(graph: TeamGraph, values: dict) -> list:
    """Per robot, (K_r,7) rows of the poses `values` (key -> Pose3) holds, NaN elsewhere."""
    guessed = [
        (r, k, values[key].matrix())
        for r, times in enumerate(graph.node_times)
        for k in range(len(times))
        if (key := pose_key(r, k)) in values
    ]
    robot, index, m = zip(*guessed) if guessed else ((), (), np.zeros((0, 4, 4)))
    return grids_rows(pose_grids(graph.node_times, robot, index, np.array(m)))


def start_only(graph: TeamGraph, initial: dict | None, start_from: str, wall: float):
    """A batch solve stopped before LM began (a signal during its incremental pass): partial,
    its estimate the LM iterate it would have started from, `initial` (None: the graph's
    guess); no session is built, so the stop returns at once."""
    guess = guess_rows(graph, graph.initial)
    return TeamResult(
        "batch",
        graph.node_times,
        guess if initial is None else guess_rows(graph, initial),
        [np.full((len(t), 7), np.nan) for t in graph.node_times],
        guess,
        np.zeros(0),
        wall,
        graph,
        {},
        {},
        partial=True,
        decisions=list(graph.decisions),
        batch_start=f"{start_from}; stopped before Levenberg-Marquardt",
    )
