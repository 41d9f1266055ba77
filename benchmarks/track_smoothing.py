"""One camera track smoothed with its candidates decided: the graph a candidate tracker's
decisions (seed 000 Sec. V, `graphloc.hypotheses.HypothesisTracker`) or a known choice (seed
004 Sec. III Table 1: the genuine P3P solution of every frame) leave behind -- pose_key(robot, k)
per frame, a BetweenFactorPose3 per odometry step and the chosen candidate of each frame as a
prior (`graphloc.factors.mixture.component_factors`, the one route from a CandidateSet to a
factor). `track_graph` builds it; `smooth_track` solves it in a batch `graphloc.session.Session`
(Levenberg-Marquardt over all poses).
"""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.mixture import candidate_covariances, component_factors
from graphloc.factors.robust import Kernel
from graphloc.keys import pose_key
from graphloc.seams import Decision, Odometry
from graphloc.session import Session, SessionConfig


def track_graph(
    candidates: list[CandidateSet | None],
    odometry: list[Odometry | None],
    chosen: list[int],
    initial: list[gtsam.Pose3 | None] | None = None,
    robot: int = 0,
    default_sigmas: tuple[float, float] = (0.02, 0.05),
    kernel: Kernel = Kernel("cauchy", 1.0),
) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """A track with its candidates chosen, as one factor graph for `graphloc.session.Session`.
    candidates[k]: frame k's CandidateSet (None: no observation); odometry[k]: the step from
    frame k-1 to k (odometry[0] unused); chosen[k]: index of frame k's chosen candidate, -1 for
    none. Factors: BetweenFactorPose3 per odometry step, then the chosen candidates' mixture
    components (covariance: CandidateSet.covariance, else `default_sigmas` [rad, m]; robust
    `kernel`: near the P3P fold a committed candidate can sit far outside its first-order
    covariance -- Kernel() for plain Gaussian priors). Initial values: initial[k] where given
    (e.g. the tracker's decided poses), the first chosen frame at its candidate's pose if not,
    chained through the odometry backwards before the first chosen frame and forwards across
    frames without one. ValueError if the lists disagree in length or nothing is chosen."""
    n = len(candidates)
    if not (n == len(odometry) == len(chosen)) or (initial is not None and len(initial) != n):
        raise ValueError(
            f"track_graph: {n} candidate sets, {len(odometry)} odometry steps, "
            f"{len(chosen)} choices"
            + ("" if initial is None else f" and {len(initial)} initial poses")
            + " must match"
        )
    frames = [k for k in range(n) if chosen[k] >= 0]
    if not frames:
        raise ValueError("track_graph: no frame has a chosen candidate")
    graph = gtsam.NonlinearFactorGraph()
    for k in range(1, n):
        if not isinstance(odometry[k], Odometry):
            raise ValueError(
                f"track_graph: odometry[{k}] must be an Odometry, got {type(odometry[k]).__name__}"
            )
        noise = gtsam.noiseModel.Gaussian.Covariance(odometry[k].covariance)
        graph.add(
            gtsam.BetweenFactorPose3(
                pose_key(robot, k - 1), pose_key(robot, k), odometry[k].relative, noise
            )
        )
    for k in frames:
        cov = candidate_covariances(candidates[k], default_sigmas)
        factors = component_factors(
            candidates[k], pose_key(robot, k), covariances=cov, kernel=kernel
        )
        graph.add(factors[chosen[k]])
    poses = [None] * n if initial is None else list(initial)
    first = frames[0]
    if poses[first] is None:
        poses[first] = candidates[first].poses()[chosen[first]]
    for k in range(first - 1, -1, -1):  # before the first choice a tracker's poses may be pseudo
        poses[k] = poses[k + 1].compose(odometry[k + 1].relative.inverse())
    for k in range(first + 1, n):
        if poses[k] is None:
            poses[k] = poses[k - 1].compose(odometry[k].relative)
    values = gtsam.Values()
    for k, p in enumerate(poses):
        values.insert(pose_key(robot, k), p)
    return graph, values


def decided(decisions: list[Decision]) -> tuple[list[int], list[gtsam.Pose3 | None]]:
    """A tracker's decisions as `track_graph`'s (chosen, initial): the committed candidate of
    every locked frame and the committed track's pose."""
    chosen = [d.committed if d.locked else -1 for d in decisions]
    return chosen, [d.pose if d.locked else None for d in decisions]


def smooth_track(
    candidates: list[CandidateSet | None],
    odometry: list[Odometry | None],
    chosen: list[int],
    robot: int = 0,
    kernel: Kernel = Kernel(),
) -> np.ndarray:
    """`track_graph` solved by a batch Session (seed 004 Table 1's graphloc column: plain
    Gaussian priors from the resection covariance by default). Returns the smoothed camera
    centres (F,3)."""
    graph, values = track_graph(candidates, odometry, chosen, robot=robot, kernel=kernel)
    session = Session(SessionConfig(mode="batch"))
    session.add(graph, values)
    est = session.estimate()
    return np.stack([est.atPose3(pose_key(robot, k)).translation() for k in range(len(candidates))])
