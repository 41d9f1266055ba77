"""The state types of `graphloc.hypotheses.pose_graph`: its settings (`PoseGraphConfig`), one
measurement with alternatives (`Ambiguity`) and one branch (`Branch`: an iSAM2, its choices, and
the factors and poses gathered for its next update)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import gtsam


@dataclass
class PoseGraphConfig:
    window: int = 10  # steps from a branching (the first since a judgement) to the judgement
    max_window: int = 100  # steps a measurement may stay open before the best branch is taken
    margin: float = 20.0  # chi-square gap that prunes a branch
    max_branches: int = 4
    # chi-square of choosing "no measurement" (unset: the 0.999 quantile, 3 dof 2D / 6 dof 3D)
    null_penalty: float | None = None
    # a null child is dropped at once when a combination's predicted chi-square (an upper bound
    # of its rise) is below the null's exact cost by more than this: the estimate explains it
    null_margin: float = 0.0
    settle: int = 1  # extra iSAM2 iterations of every branch before a judgement
    batch: int = 10  # steps per iSAM2 update (a judgement updates at once)
    flush_to_branch: bool = True  # update the iSAM2s before a branching's predictions
    defer: int = 20  # steps a new bridge's tail stays out of the iSAM2s (a switch costs no copy)
    sigmas: tuple = (0.05, 0.05, 0.01)  # a measurement without information (Pose2 / Pose3 order)
    # degrees of freedom of a Student-t on the candidates of a measurement with alternatives
    # (inf: Gaussian); finite: `branching.heavy_tailed`, its branches scored by that loss
    candidate_dof: float = math.inf
    prior_sigma: float = 1e-4
    relinearize_threshold: float = 0.1  # iSAM2's defaults
    relinearize_skip: int = 10
    bound_chain: int = 5000  # longest chain a branching's lower bound is computed along
    marginal_chain: int = 50  # from this chain length on, also the bound from marginals


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
    slot: int = -1  # decided with a factor: its index in the engine's graph of decided factors


@dataclass
class Branch:
    isam: gtsam.ISAM2
    choice: dict = field(default_factory=dict)  # ambiguity index -> candidate, undecided ones
    score: float = 0.0  # chi-square of its factors + nulls (judged, or parent + predicted rise)
    pending: list = field(default_factory=list)  # (factor, ambiguity index or None) not in it
    guess: dict = field(default_factory=dict)  # key -> initial pose, poses not in the iSAM2

    def flush(self) -> None:
        """One iSAM2 update with the factors and poses gathered since the last."""
        if self.pending or self.guess:
            graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
            for factor, _ in self.pending:
                graph.add(factor)
            for key, pose in self.guess.items():
                values.insert(key, pose)
            self.isam.update(graph, values)
            self.pending, self.guess = [], {}

    def first_pending(self, position: dict) -> float:
        return min((position[k] for k in self.guess), default=float("inf"))
