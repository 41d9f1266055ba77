"""Incremental multi-hypothesis inference for pose graphs whose measurements have discrete
alternatives: K candidate relative poses (ambiguous odometry, ambiguous loop closures) and
optionally a "null" component (a loop closure that may be an outlier), 2D (Pose2) and 3D
(Pose3), on GTSAM's iSAM2: a bounded set of branches, each one iSAM2, judged by the whole
graph's chi-square every `window` steps (the design: docs/design_algorithms.md, "Pose-graph
hypotheses"). Keys are `X(id)`.
"""

from __future__ import annotations

import math
from dataclasses import replace

import gtsam
from gtsam.symbol_shorthand import X

from graphloc.hypotheses import branching as br
from graphloc.hypotheses.pose_graph_refine import redecided, refinement
from graphloc.hypotheses.pose_graph_state import Ambiguity, Branch, PoseGraphConfig

__all__ = ["Ambiguity", "Branch", "PoseGraphConfig", "PoseGraphHypotheses"]


class PoseGraphHypotheses:
    """Feed measurements step by step (`step`), each step the edges that end at the newest
    pose; `choices()` are the decisions so far, `finish()` the final estimate."""

    def __init__(self, dim: int, config: PoseGraphConfig | None = None):
        self.dim, self.config = dim, config or PoseGraphConfig()
        if self.config.null_penalty is None:  # chi-square 0.999 quantiles
            self.config = replace(self.config, null_penalty=16.27 if dim == 2 else 22.46)
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
        self.bridges: set[int] = set()  # indices of ambiguities no factor spans yet
        self.steps = 0
        self.gathered = 0  # steps not yet in the iSAM2s
        self.window_start: int | None = None  # the step the running judgement window began
        counted = ("branchings", "rebuilds", "judgements", "forced", "bounded", "redecided")
        self.stats = dict.fromkeys(counted, 0)
        self.edge_cov: list = []  # by position: covariance of the edge from the previous pose

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
        self.step_start = len(self.order)  # positions from here on are this step's poses
        for index, m in measurements:
            source, target = X(m.source), X(m.target)
            dof = self.config.candidate_dof if m.ambiguous else math.inf
            poses, factors = br.candidate_factors(
                m, source, target, self.dim, self.config.sigmas, dof
            )
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
                chain = self.position[source] == len(self.order) - 1
                # a robust edge's information is not its Gaussian's: no chain bound through it
                bounded = chain and math.isinf(dof)
                self._register(target, br.covariance_of(factors[0]) if bounded else None)
                if len(factors) > 1:
                    position = self.position[target]
                    amb = Ambiguity(index, factors, poses, (source, target), position, self.steps)
                    self.ambiguities[index] = amb
                    self.bridges.add(index)
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
            self.ambiguities[i]
            for i in sorted(self.bridges)
            if any(min(s, t) < self.ambiguities[i].position <= max(s, t) for s, t in spans)
        ]
        opened += loops
        if opened:
            if self.config.flush_to_branch:  # predictions from an estimate of every factor
                for b in self.branches:
                    b.flush()
                self.gathered = 0
            guesses = [self._guesses(b, new_poses, keep=False) for b in self.branches]
            self._branch(opened, certain, new_poses, guesses)
        for b in self.branches:
            self._guesses(b, new_poses)
            b.pending += [(f, None) for f in certain]
            for amb in self._step_ambiguities(new_poses, loops):
                f = amb.factors[b.choice[amb.index]]
                if f is not None:
                    b.pending.append((f, amb.index))
        for f in certain:
            self.common.add(f)
        self.steps += 1
        self.gathered += 1
        young = any(
            self.steps - self.ambiguities[i].added < self.config.defer for i in self.bridges
        )
        if self.gathered >= self.config.batch and not young:
            for b in self.branches:
                b.flush()
            self.gathered = 0
        if len(self.branches) == 1:
            self.window_start = None
            self._decide()
        else:  # judged `window` steps into the window (branchings inside it do not restart
            # it) and at once when the oldest open measurement has waited `max_window` steps
            oldest = min(self.ambiguities[i].opened for i in self.open)
            force = self.steps - oldest >= self.config.max_window
            if force or self.steps - self.window_start >= self.config.window:
                self.judge(force=force)

    # ---- branching -----------------------------------------------------------------------
    def _branch(self, opened, certain, new_poses, guesses) -> None:
        """Every branch times every combination of the opened measurements' candidates: the
        best `max_branches` by the predicted chi-square of the step's factors (a place kept
        for a candidate of a measurement with a null, `_survivors`), without those whose lower
        bound (`branching.lower_bound_chi2`) exceeds their parent's best prediction by more
        than `margin`."""
        self.stats["branchings"] += 1
        for a in opened:
            a.state, a.opened = "open", self.steps
            self.open.add(a.index)
            self.bridges.discard(a.index)
        bridges = sorted((a for a in opened if a.position >= 0), key=lambda a: a.position)
        loops = [a for a in opened if a.position < 0]
        combos = br.combinations([len(a.factors) for a in bridges + loops], limit=4096)
        children = []
        for parent, guess in zip(self.branches, guesses):
            children += self._children(parent, guess, bridges, loops, combos, certain)
        children.sort(key=lambda child: child[0])
        kept, reused = [], set()
        for chi2, parent, combo, moves, estimate in self._survivors(children, bridges + loops, 2):
            choice = dict(parent.choice)
            choice.update({a.index: k for a, k in zip(bridges + loops, combo)})
            frontier = min(parent.first_pending(self.position), self.step_start)
            pending_only = all(start >= frontier for start, _ in moves)
            if pending_only and id(parent) not in reused:  # the switched tails are not in it
                reused.add(id(parent))
                child = Branch(parent.isam, choice, chi2)
                switched = {i for i, k in choice.items() if parent.choice.get(i, k) != k}
                child.pending = [
                    (self.ambiguities[i].factors[choice[i]] if i in switched else f, i)
                    for f, i in parent.pending
                ]
                child.guess = {
                    k: br.moved(p, self.position[k], moves) for k, p in parent.guess.items()
                }
                kept.append(child)
            else:
                values = gtsam.Values(estimate)
                for k, p in parent.guess.items():
                    values.insert(k, p)
                isam = self._rebuild(choice, br.moved_values(values, self.order, moves, self.dim))
                kept.append(Branch(isam, choice, chi2))
        self.branches = kept
        if self.window_start is None:
            self.window_start = self.steps

    def _survivors(self, ranked: list, opened: list, combo: int) -> list:
        """The best `max_branches` of `ranked` (sorted; item[combo]: the combination of the
        `opened` measurements' components), except that a measurement with a null component
        whose candidates all rank behind its null keeps its best candidate, in place of the
        worst survivor not kept so: a candidate is ranked by its predicted chi-square, the
        whole residual charged to its factor (an upper bound of its cost), the null by its
        exact cost, so the null children could fill every place before a judgement compares
        the two on the optimized graph."""
        kept = list(ranked[: self.config.max_branches])
        rest = ranked[self.config.max_branches :]
        reserved = 0
        for slot, a in enumerate(opened):
            null = len(a.factors) - 1
            if a.factors[null] is not None or any(r[combo][slot] != null for r in kept):
                continue
            spare = next((r for r in rest if r[combo][slot] != null), None)
            if spare is not None and reserved < len(kept) - 1:
                reserved += 1
                kept[len(kept) - reserved] = spare
        return sorted(kept, key=lambda r: r[0])

    def _children(self, parent, guess, bridges, loops, combos, certain) -> list:
        """[(the parent's score plus the predicted chi-square, parent, combination, tail moves,
        parent's estimate)] of one parent, ranked, the bound-pruned ones left out."""
        c = self.config
        estimate = parent.isam.calculateEstimate()

        def pose(key):
            if guess.exists(key):
                return guess.atPose2(key) if self.dim == 2 else guess.atPose3(key)
            if key in parent.guess:
                return parent.guess[key]
            return estimate.atPose2(key) if self.dim == 2 else estimate.atPose3(key)

        keys = {k for f in certain for k in f.keys()}
        keys |= {k for a in loops for f in a.factors if f is not None for k in f.keys()}
        keys |= {k for a in bridges for k in a.keys}
        poses = {k: pose(k) for k in keys}
        positions = {k: self.position[k] for k in keys}
        spec = [
            (self.position[a.keys[0]], a.keys[0], a.position, a.keys[1], a.poses,
             parent.choice[a.index])
            for a in bridges
        ]  # fmt: skip
        ranked = []
        for combo in combos:
            moves = br.tail_moves(spec, dict(enumerate(combo[: len(bridges)])), poses)
            factors, penalty = list(certain), 0.0
            for a, k in zip(loops, combo[len(bridges) :]):
                if a.factors[k] is None:
                    penalty += c.null_penalty
                else:
                    factors.append(a.factors[k])
            chi2 = br.predicted_chi2(factors, positions, poses, moves) + penalty
            ranked.append((chi2, combo, moves, factors, penalty))
        ranked.sort(key=lambda r: r[0])
        best = ranked[0][0]
        out = []
        marginal = br.marginals(
            parent.isam, estimate, pose, self.order, self.position, self.edge_cov
        )
        for chi2, combo, moves, factors, penalty in self._survivors(ranked, bridges + loops, 1):
            margin = c.null_margin if penalty else c.margin  # a null's cost is exact
            if chi2 > best + margin:
                need = best + margin - penalty
                bounds = (self._bound(f, pose, moves, marginal, need) for f in factors)
                bound = penalty + max(bounds, default=0.0)
                if bound > best + margin:
                    self.stats["bounded"] += 1
                    continue
            out.append((parent.score + chi2, parent, combo, moves, estimate))
        return out

    def _bound(self, factor, pose, moves, marginal, need: float) -> float:
        """A lower bound of the rise of the optimal chi-square when a between factor joins:
        `branching.lower_bound_chi2` along the insertion chain (when it is one, no longer than
        `bound_chain`), else or when that is not above `need` and the chain is longer than
        `marginal_chain`, the larger with `branching.marginal_bound_chi2` (marginals)."""
        keys = factor.keys()
        if len(keys) != 2:
            return 0.0
        first, last = self.position[keys[0]], self.position[keys[1]]
        values = gtsam.Values()
        for key in keys:
            values.insert(key, br.moved(pose(key), self.position[key], moves))
        bound = 0.0
        covariances = self.edge_cov[first + 1 : last + 1]
        chain_ok = all(cov is not None for cov in covariances)
        if 0 <= first < last <= first + self.config.bound_chain and chain_ok:
            if self.dim == 2:
                chain = br.chain_poses_2d(pose, self.order, first, last, moves)
            else:
                chain = [br.moved(pose(self.order[q]), q, moves) for q in range(first, last + 1)]
            bound = br.lower_bound_chi2(factor, values, chain, covariances)
        if bound <= need and abs(last - first) > self.config.marginal_chain:
            cov_a, cov_b = marginal(keys[0]), marginal(keys[1])
            if cov_a is not None and cov_b is not None:
                bound = max(bound, br.marginal_bound_chi2(factor, values, cov_a, cov_b))
        return bound

    def _rebuild(self, choice: dict, values: gtsam.Values) -> gtsam.ISAM2:
        """A new iSAM2 of the known poses under `choice` (this step's factors not yet in),
        linearized at `values`."""
        self.stats["rebuilds"] += 1
        graph = gtsam.NonlinearFactorGraph(self.common)
        for index, k in choice.items():
            amb = self.ambiguities[index]
            if amb.added < self.steps and amb.factors[k] is not None:
                graph.add(amb.factors[k])
        return br.fresh_isam(self.params, graph, values)

    # ---- judging -------------------------------------------------------------------------
    def judge(self, force: bool = False) -> None:
        """Score every branch by its chi-square, prune by `margin` (all but the best when
        `force`), decide what the survivors agree on."""
        c = self.config
        self.stats["judgements"] += 1
        self.stats["forced"] += int(force and len(self.branches) > 1)
        for b in self.branches:
            b.flush()
            for _ in range(c.settle):
                b.isam.update()
            nulls = sum(1 for i, k in b.choice.items() if self.ambiguities[i].factors[k] is None)
            estimate = b.isam.calculateEstimate()
            b.score = 2.0 * b.isam.getFactorsUnsafe().error(estimate) + c.null_penalty * nulls
        self.branches.sort(key=lambda b: b.score)
        best = self.branches[0].score
        keep = 1 if force else c.max_branches
        self.branches = [b for b in self.branches if b.score <= best + c.margin][:keep]
        self.window_start = self.steps if len(self.branches) > 1 else None
        self._decide()

    def _decide(self) -> None:
        for index in sorted(self.open):
            amb = self.ambiguities[index]
            values = {b.choice[amb.index] for b in self.branches}
            if len(values) == 1:
                amb.state, amb.choice = "decided", values.pop()
                self.open.discard(index)
                if amb.factors[amb.choice] is not None:
                    amb.slot = self.common.size()
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

    def undecided_count(self) -> int:
        """Measurements no factor has spanned yet (their choice is the first candidate)."""
        return len(self.bridges)

    def current(self, node: int):
        """The best branch's estimate of pose `node` (its gathered steps updated first)."""
        self.branches[0].flush()
        return br.estimate_of(self.branches[0].isam, X(node), self.dim)

    def finish(self, settle: int = 10, refine: bool = True, redecide: int = 10) -> gtsam.Values:
        """The best branch's estimate after a final forced judgement: Gauss-Newton iterations
        of its iSAM2 (every variable whose step exceeds the relinearization threshold
        relinearized) until none is relinearized, at most `settle`, the full back-substitution
        (`calculateBestEstimate`, no wildfire cut-off); with `refine`, Levenberg-Marquardt on
        the branch's graph from there (iSAM2 leaves each variable linearized up to its
        relinearization threshold away from the optimum; this removes that last error), and
        the measurements with a null component decided again at that optimum
        (`pose_graph_refine.redecided`, at most `redecide` rounds). `final_graph`: the graph
        of that estimate."""
        if len(self.branches) > 1:
            self.judge(force=True)
        self.branches[0].flush()
        isam = self.branches[0].isam
        empty = gtsam.NonlinearFactorGraph()
        for _ in range(settle):
            result = isam.update(empty, gtsam.Values(), force_relinearize=True)
            if result.getVariablesRelinearized() == 0:
                break
        estimate = isam.calculateBestEstimate()
        self.final_graph = isam.getFactorsUnsafe()
        if refine:
            graph = self.final_graph = gtsam.NonlinearFactorGraph(self.common)  # at their slots
            for index in self.bridges:  # never spanned: their first candidate
                graph.add(self.ambiguities[index].factors[self.branches[0].choice[index]])
            estimate = gtsam.LevenbergMarquardtOptimizer(graph, estimate, refinement()).optimize()
            estimate, changed = redecided(
                graph, estimate, self.ambiguities.values(), self.config.null_penalty, redecide
            )
            self.stats["redecided"] += changed
        return estimate

    # ---- helpers -------------------------------------------------------------------------
    def _register(self, key: int, covariance=None) -> None:
        self.position[key] = len(self.order)
        self.order.append(key)
        self.edge_cov.append(covariance)

    def _identity(self):
        return gtsam.Pose2() if self.dim == 2 else gtsam.Pose3()

    def _guesses(self, b: Branch, new_poses, keep: bool = True) -> gtsam.Values:
        """Initial values of the step's new poses: the source's estimate (or guess, when it is
        not in the iSAM2 yet) composed with the branch's candidate; kept in `b.guess`."""
        values, cache = gtsam.Values(), dict(b.guess)
        for target, source, what in new_poses:
            start = cache[source] if source in cache else br.estimate_of(b.isam, source, self.dim)
            pose = what.poses[b.choice[what.index]] if isinstance(what, Ambiguity) else what
            cache[target] = start.compose(pose)
            values.insert(target, cache[target])
        if keep:
            b.guess = cache
        return values

    @staticmethod
    def _step_ambiguities(new_poses, loops):
        return [w for _, _, w in new_poses if isinstance(w, Ambiguity)] + list(loops)
