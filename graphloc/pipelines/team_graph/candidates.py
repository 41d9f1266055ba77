"""Candidate sets (P3P, seed 000 / 001 / 004) -> factors: one HypothesisTracker per
(observer, target) stream decides causally; a decided candidate becomes one robust factor."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.candidates import CandidateSet
from graphloc.factors.mixture import candidate_covariances
from graphloc.factors.robust import robust_noise
from graphloc.hypotheses import HypothesisTracker
from graphloc.io import SkipReport
from graphloc.keys import pose_key
from graphloc.pipelines.team_graph.config import GraphConfig, adjoint_cov
from graphloc.pipelines.team_graph.motion import Timeline, compose_steps, dead_reckoning
from graphloc.run import TeamRun
from graphloc.seams import Odometry


@dataclass
class Decision:
    """What happened to one candidate set: where each candidate puts the observer's body
    (K,3 world), the committed candidate (-1: none), its posterior (else the largest one) and
    the committed body pose (x, y, z, qx, qy, qz, qw; NaN if none); same_pose: the candidates
    that are the committed one's pose within their covariances (`_same_pose`), it included."""

    time: float
    robot: int
    target: int
    candidates_xyz: np.ndarray
    committed: int
    probability: float
    pose: np.ndarray
    same_pose: list


SAME_POSE_GATE = 12.59  # chi2(6) at 95 %: two candidates this close are one pose for the decision


def same_pose(poses: list, cov: np.ndarray, j: int) -> list[int]:
    """Candidate j and the candidates that are the same pose within their covariances
    (Mahalanobis^2 of the difference below SAME_POSE_GATE): near the P3P fold two solutions
    nearly coincide and share the posterior, and either one is the answer."""
    out = []
    for i, p in enumerate(poses):
        e = gtsam.Pose3.Logmap(poses[j].between(p))
        if i == j or e @ np.linalg.solve(cov[i] + cov[j], e) < SAME_POSE_GATE:
            out.append(i)
    return out


def candidate_factors(
    run: TeamRun,
    config: GraphConfig,
    timeline: Timeline,
    step_rel: list,
    factors: list,
    skips: SkipReport,
    progress: bool = False,
) -> tuple[list, dict]:
    """Decide every candidate set (one tracker per (observer, target) stream) and append the
    decided ones as factors; returns the decisions and the decided observer poses
    (robot -> {node: Pose3})."""
    node_times, nearest = timeline.node_times, timeline.nearest
    decisions, decided_pose = [], {}
    streams: dict = {}
    for o in run.observations:
        streams.setdefault((o.robot, o.target), []).append(o)
    for (r, ti), obs in tqdm(
        streams.items(), desc="deciding candidate sets", disable=not progress, unit="stream"
    ):
        target = run.robots[ti]
        if target.initial_pose is None:
            skips.add(
                "target_unplaced",
                f"robot {run.robots[r].name}: {len(obs)} candidate sets on robot "
                f"{target.name}, which has no initial pose",
                len(obs),
            )
            continue
        target_track = dead_reckoning(target, step_rel[ti], config)
        tracker = HypothesisTracker(config.tracker)
        prev = None
        for o in obs:
            k = nearest(r, o.time)
            if k < 0 or (prev is not None and k == prev):
                skips.add(
                    "no_pose_at_time",
                    f"robot {run.robots[r].name}: candidate set at {o.time} has no "
                    f"(new) pose within the sync tolerance",
                )
                continue
            kt = nearest(ti, o.time)
            if kt < 0:
                skips.add(
                    "no_pose_at_time",
                    f"robot {target.name}: seen at {o.time} with no pose within the sync tolerance",
                )
                continue
            E = o.body_T_sensor
            X_t, P_t = target_track[kt]
            # the candidates (target_T_sensor) in the world through the target's pose, its
            # uncertainty added
            seen = o.candidates.poses()  # target_T_sensor
            world = [X_t.compose(p) for p in seen]
            cand_cov = candidate_covariances(o.candidates, config.tracker.default_sigmas)
            cov = cand_cov + np.stack([adjoint_cov(p.inverse(), P_t) for p in seen])
            cs = CandidateSet(
                np.stack([p.rotation().matrix() for p in world]),
                np.stack([p.translation() for p in world]),
                o.candidates.scores,
                o.time,
                run.robots[r].name,
                target.name,
                o.candidates.source,
                o.candidates.meta,
                cov,
            )
            odo = None
            if prev is not None:
                rel, cov = compose_steps(step_rel[r], prev, k, config)
                odo = Odometry(E.inverse().compose(rel).compose(E), adjoint_cov(E.inverse(), cov))
            d = tracker.update(cs, odo)
            prev = k
            pose = np.full(7, np.nan)
            cluster = (
                same_pose(world, cs.covariance, d.committed)
                if d.locked and d.committed >= 0
                else []
            )
            decided = bool(cluster) and d.probabilities[cluster].sum() >= config.decision_threshold
            if decided:
                j = d.committed
                body = world[j].compose(E.inverse())
                kernel = config.kernels.kernel("candidate")
                if target.static:  # the target's pose is known: a prior on the observer
                    noise = robust_noise(
                        gtsam.noiseModel.Gaussian.Covariance(adjoint_cov(E, cs.covariance[j])),
                        kernel,
                    )
                    factor = gtsam.PriorFactorPose3(pose_key(r, k), body, noise)
                else:
                    # observer_T_target = E target_T_sensor^-1, covariance moved to the target's
                    # side
                    noise = robust_noise(
                        gtsam.noiseModel.Gaussian.Covariance(adjoint_cov(seen[j], cand_cov[j])),
                        kernel,
                    )
                    factor = gtsam.BetweenFactorPose3(
                        pose_key(r, k), pose_key(ti, kt), E.compose(seen[j].inverse()), noise
                    )
                factors.append((max(node_times[r][k], node_times[ti][kt]), factor, "candidate"))
                decided_pose.setdefault(r, {})[k] = body
                q = gtsam.Rot3(body.rotation().matrix()).toQuaternion()
                pose = np.r_[body.translation(), q.x(), q.y(), q.z(), q.w()]
            prob = (
                float(d.probabilities[d.committed])
                if d.committed >= 0
                else float(np.max(d.probabilities, initial=0))
            )
            xyz = np.array([p.compose(E.inverse()).translation() for p in world])
            decisions.append(
                Decision(
                    o.time,
                    r,
                    ti,
                    xyz,
                    int(d.committed) if decided else -1,
                    prob,
                    pose,
                    cluster if decided else [],
                )
            )
    return decisions, decided_pose
