"""Incremental multi-hypothesis inference for pose graphs whose measurements have discrete
alternatives: K candidate relative poses (ambiguous odometry, ambiguous loop closures) and
optionally a "null" component (a loop closure that may be an outlier), 2D (Pose2) and 3D
(Pose3), on GTSAM's iSAM2.

Design (deferred decisions over a bounded set of branches, each one iSAM2):

* A measurement that introduces a new pose is a *bridge* while no factor spans it (no factor
  joins a pose before it to a pose after it, in insertion order). Its candidates cannot be told
  apart yet (the tail moves rigidly with it, every candidate has the same optimal error), so
  it enters every branch with its first candidate and no branch is created.
* When factors arrive that span bridges, or an ambiguous loop closure arrives, the engine
  branches: every surviving branch times every combination of the newly open measurements'
  candidates. Combinations are ranked by the chi-square of the step's new factors at the
  branch's estimate with the switched tails moved rigidly (`branching.tail_moves`), and the
  best `max_branches` are kept. A child that switches nothing reuses its parent's iSAM2;
  the others are new iSAM2s built from their factor list at the moved estimate.
* Every branch receives every later factor. Every `window` steps after a branching, each
  branch is scored by the chi-square of all its factors at its estimate (2 x the error GTSAM
  reports, after `settle` extra iSAM2 iterations) plus `null_penalty` per null component it
  chose (the negative log of a null's prior odds, as in a max-mixture / switchable constraint);
  branches worse than the best by more than `margin` are pruned (a chi-square test on the
  difference of two nested fits). A measurement is decided when every surviving branch holds
  the same candidate; `max_window` steps after the oldest open measurement the best branch is
  taken alone (bounded deferral).

The score is the whole graph's chi-square, computed only at judgements (not per step), so the
cost per step is one iSAM2 update per branch; with one branch (no open measurement) that is
plain iSAM2. Keys are `X(id)`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X

from graphloc.hypotheses import branching as br


@dataclass
class PoseGraphConfig:
    window: int = 10  # steps between judgements after a branching
    max_window: int = 300  # steps a measurement may stay open before the best branch is taken
    margin: float = 20.0  # chi-square gap that prunes a branch
    max_branches: int = 8
    null_penalty: float = 16.3  # chi-square of choosing "no measurement" (3 dof, p = 0.999)
    settle: int = 1  # extra iSAM2 iterations of every branch before a judgement
    sigmas: tuple = (0.05, 0.05, 0.01)  # a measurement without information (Pose2 / Pose3 order)
    prior_sigma: float = 1e-4
    relinearize_threshold: float = 0.1  # iSAM2's defaults
    relinearize_skip: int = 10


@dataclass
class Ambiguity:
    index: int  # the measurement's index in the caller's list
    factors: list  # one factor per candidate, None for the null component
    poses: list  # candidate poses (source -> target)
    keys: tuple  # (source key, target key)
    position: int  # the new pose's insertion position (bridge), else -1
    added: int = 0  # the step it arrived in
    state: str = "bridge"  # bridge | open | decided
    opened: int = -1  # the step it was opened in
    choice: int = 0  # decided (or provisional) candidate


@dataclass
class Branch:
    isam: gtsam.ISAM2
    choice: dict = field(default_factory=dict)  # ambiguity index -> candidate, undecided ones
    score: float = 0.0


class PoseGraphHypotheses:
    """Feed measurements step by step (`step`), each step the edges that end at the newest
    pose; `choices()` are the decisions so far, `finish()` the final estimate."""

    def __init__(self, dim: int, config: PoseGraphConfig | None = None):
        self.dim, self.config = dim, config or PoseGraphConfig()
        c = self.config
        self.params = gtsam.ISAM2Params()
        self.params.setRelinearizeThreshold(c.relinearize_threshold)
        self.params.relinearizeSkip = c.relinearize_skip
        self.common = gtsam.NonlinearFactorGraph()  # certain and decided factors
        self.order: list[int] = []  # keys by insertion
        self.position: dict[int, int] = {}
        self.ambiguities: dict[int, Ambiguity] = {}
        self.branches: list[Branch] = []
        self.open: set[int] = set()  # indices of open ambiguities
        self.steps = 0
        self.last_branching = -1
        self.stats = {"branchings": 0, "rebuilds": 0, "judgements": 0, "forced": 0}

    # ---- input ---------------------------------------------------------------------------
    def start(self, node: int, pose_values=None) -> None:
        """The first pose, held by a prior (at `pose_values`, else the origin)."""
        pose = br.pose_of(pose_values, self.dim) if pose_values is not None else self._identity()
        noise = gtsam.noiseModel.Isotropic.Sigma(3 if self.dim == 2 else 6, self.config.prior_sigma)
        factor = br.prior(self.dim, X(node), pose, noise)
        self.common.add(factor)
        self._register(X(node))
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        graph.add(factor)
        values.insert(X(node), pose)
        self.branches = [Branch(br.fresh_isam(self.params, graph, values))]

    def step(self, measurements) -> None:
        """One step: `measurements` [(index, m)], m with `source`, `target`, `candidates`,
        `information`, `null` (graphloc.datasets.pose_graph_file.Measurement); every edge joins
        known poses or introduces one new pose."""
        certain, new_poses, loops, spans = [], [], [], []
        for index, m in measurements:
            source, target = X(m.source), X(m.target)
            poses = [br.pose_of(v, self.dim) for v in m.candidates]
            infos = m.information or [None] * len(poses)
            factors = [
                br.between(
                    self.dim, source, target, p, br.noise_of(i, self.config.sigmas, self.dim)
                )
                for p, i in zip(poses, infos)
            ]
            known = (source in self.position, target in self.position)
            if known == (True, True):
                spans.append((self.position[source], self.position[target]))
                if m.ambiguous:
                    options = factors + ([None] if m.null else [])
                    amb = Ambiguity(index, options, poses, (source, target), -1, self.steps)
                    self.ambiguities[index] = amb
                    loops.append(amb)
                else:
                    certain.append(factors[0])
            elif known == (True, False):
                self._register(target)
                if len(factors) > 1:
                    position = self.position[target]
                    amb = Ambiguity(index, factors, poses, (source, target), position, self.steps)
                    self.ambiguities[index] = amb
                    new_poses.append((target, source, amb))
                else:
                    certain.append(factors[0])
                    new_poses.append((target, source, poses[0]))
            else:
                raise ValueError(
                    f"measurement {index} (line {m.line}): {m.source} -> {m.target} does not "
                    f"start at a known pose (edges must grow the graph from its first pose)"
                )
        for b in self.branches:
            for _, _, amb in new_poses:
                if isinstance(amb, Ambiguity):
                    b.choice[amb.index] = 0
            for amb in loops:
                b.choice[amb.index] = 0
        opened = [
            a
            for a in self.ambiguities.values()
            if a.state == "bridge"
            and a.position >= 0
            and any(min(s, t) < a.position <= max(s, t) for s, t in spans)
        ]
        opened += loops
        guesses = [self._guesses(b, new_poses) for b in self.branches]
        if opened:
            self._branch(opened, certain, new_poses, guesses)
            guesses = [self._guesses(b, new_poses) for b in self.branches]
        for b, values in zip(self.branches, guesses):
            graph = gtsam.NonlinearFactorGraph()
            for f in certain:
                graph.add(f)
            for amb in self._step_ambiguities(new_poses, loops):
                f = amb.factors[b.choice[amb.index]]
                if f is not None:
                    graph.add(f)
            b.isam.update(graph, values)
        for f in certain:
            self.common.add(f)
        self.steps += 1
        if len(self.branches) == 1:
            self._decide()
        elif (self.steps - self.last_branching) % self.config.window == 0:
            oldest = min(self.ambiguities[i].opened for i in self.open)
            self.judge(force=self.steps - oldest >= self.config.max_window)

    # ---- branching -----------------------------------------------------------------------
    def _branch(self, opened, certain, new_poses, guesses) -> None:
        c = self.config
        self.stats["branchings"] += 1
        for a in opened:
            a.state, a.opened = "open", self.steps
            self.open.add(a.index)
        bridges = sorted((a for a in opened if a.position >= 0), key=lambda a: a.position)
        loops = [a for a in opened if a.position < 0]
        sizes = [len(a.factors) for a in bridges + loops]
        combos = br.combinations(sizes, limit=4096)
        step_factors_fixed = list(certain)
        children = []
        for parent, guess in zip(self.branches, guesses):
            keys = {k for f in step_factors_fixed for k in f.keys()}
            keys |= {k for a in loops for f in a.factors if f is not None for k in f.keys()}
            keys |= {k for a in bridges for k in a.keys}
            poses = {k: self._pose(parent, k, guess) for k in keys}
            spec = [
                (self.position[a.keys[0]], a.keys[0], a.position, a.keys[1], a.poses,
                 parent.choice[a.index])
                for a in bridges
            ]  # fmt: skip
            for combo in combos:
                moves = br.tail_moves(spec, dict(enumerate(combo[: len(bridges)])), poses)
                factors = list(step_factors_fixed)
                penalty = 0.0
                for a, k in zip(loops, combo[len(bridges) :]):
                    if a.factors[k] is None:
                        penalty += c.null_penalty
                    else:
                        factors.append(a.factors[k])
                positions = {k: self.position[k] for k in keys}
                chi2 = br.predicted_chi2(factors, positions, poses, moves) + penalty
                children.append((chi2, parent, combo, moves))
        children.sort(key=lambda child: child[0])
        kept, reused = [], set()
        for chi2, parent, combo, moves in children[: c.max_branches]:
            choice = dict(parent.choice)
            choice.update({a.index: k for a, k in zip(bridges + loops, combo)})
            if not moves and id(parent) not in reused:
                reused.add(id(parent))
                kept.append(Branch(parent.isam, choice, chi2))
            else:
                kept.append(Branch(self._rebuild(parent, choice, moves), choice, chi2))
        self.branches = kept
        self.last_branching = self.steps

    def _rebuild(self, parent: Branch, choice: dict, moves: list) -> gtsam.ISAM2:
        """A new iSAM2 of the known poses under `choice` (this step's factors not yet in),
        linearized at the parent's estimate with the switched tails moved."""
        self.stats["rebuilds"] += 1
        graph = gtsam.NonlinearFactorGraph(self.common)
        for index, k in choice.items():
            amb = self.ambiguities[index]
            if amb.added < self.steps and amb.factors[k] is not None:
                graph.add(amb.factors[k])
        estimate = parent.isam.calculateEstimate()
        return br.fresh_isam(
            self.params, graph, br.moved_values(estimate, self.order, moves, self.dim)
        )

    # ---- judging -------------------------------------------------------------------------
    def judge(self, force: bool = False) -> None:
        """Score every branch by its chi-square, prune by `margin` (all but the best when
        `force`), decide what the survivors agree on."""
        c = self.config
        self.stats["judgements"] += 1
        self.stats["forced"] += int(force and len(self.branches) > 1)
        for b in self.branches:
            for _ in range(c.settle):
                b.isam.update()
            nulls = sum(1 for i, k in b.choice.items() if self.ambiguities[i].factors[k] is None)
            estimate = b.isam.calculateEstimate()
            b.score = 2.0 * b.isam.getFactorsUnsafe().error(estimate) + c.null_penalty * nulls
        self.branches.sort(key=lambda b: b.score)
        best = self.branches[0].score
        keep = 1 if force else c.max_branches
        self.branches = [b for b in self.branches if b.score <= best + c.margin][:keep]
        self._decide()

    def _decide(self) -> None:
        for index in sorted(self.open):
            amb = self.ambiguities[index]
            values = {b.choice[amb.index] for b in self.branches}
            if len(values) == 1:
                amb.state, amb.choice = "decided", values.pop()
                self.open.discard(index)
                if amb.factors[amb.choice] is not None:
                    self.common.add(amb.factors[amb.choice])
                for b in self.branches:
                    del b.choice[amb.index]

    # ---- output --------------------------------------------------------------------------
    def choices(self) -> dict[int, int]:
        """Measurement index -> candidate (null = the last index) held by the best branch."""
        best = self.branches[0].choice
        out = {}
        for index, amb in self.ambiguities.items():
            out[index] = amb.choice if amb.state == "decided" else best.get(index, amb.choice)
        return out

    def undecided(self) -> int:
        return sum(1 for a in self.ambiguities.values() if a.state != "decided")

    def current(self, node: int):
        return br.estimate_of(self.branches[0].isam, X(node), self.dim)

    def finish(self, settle: int = 3) -> gtsam.Values:
        """The best branch's estimate after a final forced judgement and `settle` iterations."""
        if len(self.branches) > 1:
            self.judge(force=True)
        isam = self.branches[0].isam
        for _ in range(settle):
            isam.update()
        return isam.calculateEstimate()

    # ---- helpers -------------------------------------------------------------------------
    def _register(self, key: int) -> None:
        self.position[key] = len(self.order)
        self.order.append(key)

    def _identity(self):
        return gtsam.Pose2() if self.dim == 2 else gtsam.Pose3()

    def _guesses(self, b: Branch, new_poses) -> gtsam.Values:
        values = gtsam.Values()
        cache = {}
        for target, source, what in new_poses:
            start = cache[source] if source in cache else br.estimate_of(b.isam, source, self.dim)
            pose = what.poses[b.choice[what.index]] if isinstance(what, Ambiguity) else what
            cache[target] = start.compose(pose)
            values.insert(target, cache[target])
        return values

    def _pose(self, b: Branch, key: int, guess: gtsam.Values):
        if guess.exists(key):
            return guess.atPose2(key) if self.dim == 2 else guess.atPose3(key)
        return br.estimate_of(b.isam, key, self.dim)

    @staticmethod
    def _step_ambiguities(new_poses, loops):
        return [w for _, _, w in new_poses if isinstance(w, Ambiguity)] + list(loops)


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    """Root mean square of the position differences of two (n, >=2) arrays (x, y[, z])."""
    d = a.shape[1] if a.shape[1] in (2, 3) else 2
    return float(np.sqrt(np.mean(np.sum((a[:, :d] - b[:, :d]) ** 2, axis=1))))
