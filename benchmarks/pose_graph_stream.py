"""The pose-graph engine (`graphloc.hypotheses.pose_graph.PoseGraphHypotheses`, dim 3) behind the
HypothesisTracker's interface, `update(candidates, odometry) -> Decision`, so that both engines
can be fed the same candidate-set stream (issue 51: one engine for the team graph's candidate
sets and for pose graphs? scripts/bench_candidate_engines.py measures it).

The mapping (`PoseGraphStream`):
- node 0 is the frame the candidates are expressed in (the world), held by the engine's prior
  at the identity (`start(0)`); frame k is node k + 1;
- frame k's odometry (k >= 1) is a certain between edge node k -> node k + 1 with the
  odometry's covariance (its information);
- frame k's candidate set is one measurement node 0 -> node k + 1 whose candidates are the
  set's poses T_wc, each with the covariance the tracker uses
  (`track.capped_candidate_covariances`, the tracker's default `TrackerConfig`) as information,
  and a null component (a set may lack the genuine pose): on every set (`null="all"`), only on
  sets of fewer than the tracker's `full_count` candidates (`"partial"`: the tracker's prior,
  a complete P3P set holds the genuine solution, TrackerConfig's docstring), or on none.
  Frame 0's set introduces node 1, so the engine takes it as a bridge (no null: the engine
  gives a bridge none); every later set joins known poses and is an ambiguous loop closure;
- both edges of a frame are one `step` (odometry first: it introduces the frame's node).

The Decision of update k (causal: what the engine knows right after step k):
- locked: frame k's measurement is decided (every surviving branch holds the same component)
  on a candidate, or on the null once some set has been decided on a candidate (as the
  tracker's committed track coasting: a null decided before any candidate locks no pose);
  committed: the decided candidate (-1 for the null, or while undecided);
- probabilities: the branches' weights exp(-score / 2) (score: chi-square plus null penalties,
  judged or predicted) normalized and summed by the candidate each holds for frame k (the null's
  share is left out, so they may sum to < 1); a decided frame: 1 on its candidate;
- pose: the best branch's estimate of node k + 1 (`current`);
- relocalized: always False: a decided measurement is final in the engine (no release).

Judging: the engine's own schedule (`PoseGraphConfig.window`: `window` steps after the first
branching since its last judgement; a candidate set branches every frame).
"""

from __future__ import annotations

import math

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.datasets.pose_graph_file import Measurement
from graphloc.hypotheses import TrackerConfig
from graphloc.hypotheses.pose_graph import PoseGraphConfig, PoseGraphHypotheses
from graphloc.hypotheses.track import capped_candidate_covariances
from graphloc.seams import Decision, Odometry, check_frame

NULLS = ("all", "partial", "none")  # which sets get a null component (`PoseGraphStream`)


def pose_numbers(pose: gtsam.Pose3) -> tuple:
    """(x, y, z, qx, qy, qz, qw) of a Pose3: a pose-graph file's Pose3 candidate."""
    q, t = pose.rotation().toQuaternion(), pose.translation()
    return (*map(float, t), q.x(), q.y(), q.z(), q.w())


def information(covariance: np.ndarray) -> np.ndarray:
    """The information matrix of a covariance, symmetrized (the engine's noise model takes it)."""
    inv = np.linalg.inv(np.asarray(covariance, dtype=float))
    return 0.5 * (inv + inv.T)


def candidate_measurement(
    frame: int, candidates: CandidateSet, covariances: np.ndarray, null: bool
) -> Measurement:
    """Frame `frame`'s candidate set as a measurement node 0 -> node frame + 1 (with a null
    component when `null`)."""
    poses = [gtsam.Pose3(gtsam.Rot3(R), t) for R, t in zip(candidates.R, candidates.t)]
    return Measurement(
        line=frame,
        source=0,
        target=frame + 1,
        candidates=tuple(pose_numbers(p) for p in poses),
        information=tuple(information(c) for c in covariances),
        null=null,
    )


def odometry_measurement(frame: int, odometry: Odometry) -> Measurement:
    """Frame `frame`'s odometry as a certain edge node frame -> node frame + 1."""
    return Measurement(
        line=frame,
        source=frame,
        target=frame + 1,
        candidates=(pose_numbers(odometry.relative),),
        information=(information(odometry.covariance),),
    )


class PoseGraphStream:
    """PoseGraphHypotheses fed a candidate-set stream (module docstring: the mapping).

    stream = PoseGraphStream(PoseGraphConfig(window=1))
    d0 = stream.update(candidates_0)
    d1 = stream.update(candidates_1, odometry_1)
    """

    def __init__(
        self,
        config: PoseGraphConfig | None = None,
        null: str = "all",
        tracker_config: TrackerConfig = TrackerConfig(),
    ):
        if null not in NULLS:
            raise ValueError(f"PoseGraphStream: null must be one of {NULLS}, got {null!r}")
        self.null = null
        self.engine = PoseGraphHypotheses(3, config)
        self.engine.start(0)
        self.tracker_config = tracker_config
        self.frames = 0
        self._last_time: float | None = None
        self._anchored = False  # a frame's set has been decided on a candidate

    @staticmethod
    def set_index(frame: int) -> int:
        """The engine's measurement index of frame `frame`'s candidate set (odometry: even)."""
        return 2 * frame + 1

    def update(self, candidates: CandidateSet, odometry: Odometry | None = None) -> Decision:
        k = self.frames
        check_frame(candidates, odometry, k == 0, self._last_time, "PoseGraphStream.update")
        covariances = capped_candidate_covariances(candidates, self.tracker_config)
        step = []
        if k > 0:
            step.append((2 * k, odometry_measurement(k, odometry)))
        if len(candidates):
            null = self.null == "all" or (
                self.null == "partial" and len(candidates) < self.tracker_config.full_count
            )
            measurement = candidate_measurement(k, candidates, covariances, null)
            step.append((self.set_index(k), measurement))
        elif k == 0:
            raise ValueError("PoseGraphStream.update: the first frame needs a candidate")
        self.engine.step(step)
        self.frames += 1
        self._last_time = candidates.time
        return self._decision(k, len(candidates))

    def _decision(self, k: int, size: int) -> Decision:
        engine = self.engine
        probabilities = np.zeros(size)
        amb = engine.ambiguities.get(self.set_index(k))
        locked, committed = False, -1
        if amb is not None and amb.state == "decided":
            if amb.factors[amb.choice] is not None:
                committed = amb.choice
                probabilities[committed] = 1.0
            self._anchored = self._anchored or any(
                a.state == "decided" and a.factors[a.choice] is not None
                for a in engine.ambiguities.values()
            )
            locked = self._anchored
        elif amb is not None:
            scores = [b.score for b in engine.branches]
            best = min(scores)
            weights = [math.exp(-0.5 * (s - best)) for s in scores]
            total = sum(weights)
            for b, w in zip(engine.branches, weights):
                choice = b.choice.get(amb.index, amb.choice)
                if amb.factors[choice] is not None:
                    probabilities[choice] += w / total
        return Decision(probabilities, committed, locked, engine.current(k + 1), False)
