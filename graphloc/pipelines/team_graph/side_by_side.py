"""`SideBySide`: online passes of one `TeamGraph` from several starts stepped together,
compared by the chi-square of their factors without the robust kernels and pruned as the
evidence arrives (docs/design_team_graph.md, "Hypotheses side by side")."""

from __future__ import annotations

from collections import ChainMap
from dataclasses import replace

import gtsam
import numpy as np

from graphloc.pipelines.team_graph.graph import TeamGraph
from graphloc.pipelines.team_graph.passes import Pass, TeamResult

PRUNE_CHI2 = 50.0  # a hypothesis whose chi-square exceeds the least by this much is dropped
SETTLE_UPDATES = 5  # ... after at most this many more iSAM2 iterations of both
SAME_ESTIMATE = (0.01, 0.01)  # (m, rad): hypotheses whose latest poses agree this well are one
EARLY_CHECKS = 20  # hypotheses are compared after each of the first steps
MAX_CHECKS = 200  # hypotheses are compared at most this many times over a run (and at its end)


class SideBySide:
    """Passes of `graph` in `mode` from each of `starts` (key -> value over the graph's guess; None:
    the guess): `step(i)` steps them and compares them (the first EARLY_CHECKS steps, every
    `stride`-th, the `last`), `result()` the best; times: per start the node time before which it is
    not dropped (`start_times`)."""

    def __init__(
        self,
        graph: TeamGraph,
        mode: str,
        starts: list,
        stop=None,
        stride: int = 1,
        times: list | None = None,
    ):
        self.graph, self.mode, self.stop, self.stride = graph, mode, stop, stride
        self.passes: list = []
        self.alive: list = []
        self.times: list = []  # per pass, the node time it is judged from (None: every step)
        self.chi2 = np.zeros(0)
        self.best_at: list = []  # step -> index of the best pass then
        self.done = 0  # graph steps taken
        self.add(starts, times)

    @property
    def best(self) -> Pass:
        """The pass of least chi-square at the last comparison (the first before any)."""
        return self.passes[self.best_at[-1] if self.best_at else self.alive[0]]

    def add(self, starts: list, times: list | None = None) -> None:
        """More passes, one per start (placed at node time `times[j]`, None: judged from the
        first step), brought up to the steps already taken."""
        self.times += [None] * len(starts) if times is None else list(times)
        for s in starts:
            initial = None if s is None else ChainMap(s, self.graph.initial)
            solver = Pass(self.graph, self.mode, initial, False, self.stop)
            for i in range(self.done):
                solver.step(i)
            self.passes.append(solver)
            self.alive.append(len(self.passes) - 1)
        self.chi2 = np.concatenate([self.chi2, np.zeros(len(starts))])

    def step(self, i: int, last: bool = False) -> None:
        passes, alive = self.passes, self.alive
        self.done = i + 1
        for j in list(alive):
            try:
                passes[j].step(i)
            except ValueError:  # iSAM2 cannot solve this hypothesis: it is dropped
                if len(alive) == 1:
                    raise
                alive.remove(j)
        t = self.graph.steps[i][0]
        unjudged = {j for j in alive if self.times[j] is not None and t < self.times[j] - 1e-9}
        if len(alive) > 1:
            alive[:] = _distinct(passes, alive, unjudged)
        if len(alive) > 1 and (i % self.stride == 0 or i < EARLY_CHECKS or last):
            alive[:] = _prune(passes, alive, self.chi2, unjudged)
        self.best_at.append(min(alive, key=lambda j: self.chi2[j]))

    def result(self, partial: bool = False) -> TeamResult:
        passes, alive = self.passes, self.alive
        results = {j: passes[j].result() for j in alive}
        best = min(alive, key=lambda j: results[j].chi2)
        result = results[best]
        if len(passes) > 1:  # each pose's causal estimate from the pass best when it entered
            causal = [rows.copy() for rows in result.causal]
            for r, rows in enumerate(causal):
                for k in range(len(rows)):
                    i = passes[0].entered.get((r, k))
                    if i is not None and i < len(self.best_at):
                        rows[k] = passes[self.best_at[i]].causal_row(r, k)
            result = replace(result, causal=causal)
        return replace(
            result,
            partial=partial or result.partial,
            survivors=[results[j].values for j in alive if j != best],
            hypotheses=len(passes),
        )


def _distinct(passes: list, alive: list, unjudged: set = frozenset()) -> list:
    """The hypotheses that are not the same estimate as an earlier one: every robot's latest
    pose within SAME_ESTIMATE (m, rad) of it (they converged to one basin). Those in
    `unjudged` are kept: before the step of the node a start was placed at, the robot it
    places may hold no pose yet, so every start reads as the same estimate."""
    out = []
    for j in alive:
        mine = passes[j].latest
        if j in unjudged or not any(_same(mine, passes[i].latest) for i in out):
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


def start_times(alternatives: list, times: list) -> list | None:
    """Per start of a `SideBySide` over the guess and `alternatives` (placed at node times
    `times`, `TeamGraph.alternative_times`): its `times` entry, None for the guess; None where
    the times do not match the alternatives (a graph built without them: every step judges)."""
    return [None, *times] if len(times) == len(alternatives) else None


def _prune(passes: list, alive: list, chi2: np.ndarray, unjudged: set = frozenset()) -> list:
    """Hypotheses compared by chi-square: one more than PRUNE_CHI2 behind the best gets up to
    SETTLE_UPDATES more iSAM2 iterations, as does the best, and is dropped if still behind (those in
    `unjudged` are kept); updates `chi2`."""
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
