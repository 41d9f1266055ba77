"""Candidate sets (P3P, seed 000 / 001 / 004) -> factors: one HypothesisTracker per
(observer, target) stream decides causally; a decided candidate becomes one robust factor, or,
where the set's marker pixels are known and the target is static, the pixels themselves enter
(`camera.marker_factors`) and the candidates place the observer."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.candidates import CandidateSet
from graphloc.factors.mixture import candidate_covariances, max_mixture_factor, mixture_weights
from graphloc.factors.robust import robust_noise
from graphloc.hypotheses import HypothesisTracker
from graphloc.io import SkipReport
from graphloc.keys import pose_key
from graphloc.pipelines.team_graph.camera import marker_factors
from graphloc.pipelines.team_graph.config import GraphConfig, adjoint_cov
from graphloc.pipelines.team_graph.motion import Timeline, compose_steps, dead_reckoning
from graphloc.run import TeamRun
from graphloc.seams import Odometry


@dataclass
class Decision:
    """What happened to one candidate set: where each candidate puts the observer's body
    (K,3 world), the committed candidate (-1: none), its posterior (else the largest one) and
    the committed body pose (x, y, z, qx, qy, qz, qw; NaN if none); same_pose: the candidates
    that are the committed one's pose within their covariances (`same_pose`), it included.
    Sets of the max-mixture route (`mixture_stream`) are chosen by the solve: `committed`
    / `probability` are filled from the estimate (`solve.choose_mixtures`)."""

    time: float
    robot: int
    target: int
    candidates_xyz: np.ndarray
    committed: int
    probability: float
    pose: np.ndarray
    same_pose: list
    probabilities: np.ndarray | None = None  # (K,) every candidate's posterior (tracker)
    mixture: object = None  # max-mixture route: the MaxMixture (chosen at the estimate)
    relative: np.ndarray | None = None  # max-mixture route: (K,4,4) observer body_T_target
    candidates_quat: np.ndarray | None = None  # (K,4) x y z w: the body orientation each gives


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
    marker_points: dict,
    progress: bool = False,
) -> tuple[list, dict, dict, dict, dict]:
    """Every candidate set as factors, by one rule per (observer, target) stream:
    - the target is placed (known initial pose): the observer is placed through it; one
      HypothesisTracker decides causally and a decided candidate becomes one robust factor;
      when the target is static and the sets carry their marker pixels, the pixels become
      projection factors instead (`camera.marker_factors`; a decided candidate would count
      them twice) and the observer is placed at its first decided set, or, if the tracker never
      decides, at the stream's first set by the tracker's guess there; every candidate of that
      set is an alternative placement the batch solve also starts from (`alternatives`);
    - the target is not placed but the observer is (e.g. seed 003: a camera sees a teammate's
      base, two circle candidates): the target is placed through the observer and each set
      enters as a max-mixture of its candidates (`mixture_stream`), chosen by the solve.
    Returns the decisions, the decided observer poses (robot -> {node: Pose3}), the targets
    placed through an observer (robot -> {node: (observer, node, body_T_target)}) and each
    tracked observer's latest best guess, decided or not (robot -> (node, time, body pose,
    6x6 covariance; the hint of the inter-robot scan registration, `team_graph.scans`) and the
    alternative placements of pixel streams (robot -> ([(node, body Pose3) per candidate],
    placed by the tracker's guess, never decided)); the
    target's marker points land in `marker_points` (key -> world position)."""
    node_times, nearest = timeline.node_times, timeline.nearest
    decisions, decided_pose, placed_via, tentative, alternatives = [], {}, {}, {}, {}
    streams: dict = {}
    for o in run.observations:
        streams.setdefault((o.robot, o.target), []).append(o)
    for (r, ti), obs in tqdm(
        streams.items(), desc="deciding candidate sets", disable=not progress, unit="stream"
    ):
        target = run.robots[ti]
        if target.initial_pose is None and run.robots[r].initial_pose is not None:
            decisions += mixture_stream(
                run, config, timeline, step_rel, r, ti, obs, factors, skips, placed_via
            )
            continue
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
        pixel_route = target.static and all(o.pixels is not None for o in obs)
        first = None  # pixel route: (node, body pose per candidate, the tracker's guess)
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
            bodies = [w.compose(E.inverse()) for w in world]  # where each puts the observer
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
            if pixel_route:
                marker_factors(
                    run, config, r, k, node_times[r][k], o, factors, marker_points, skips
                )
                if first is None:
                    first = (k, bodies, bodies[int(np.argmax(d.probabilities))])
            if d.pose is not None:  # the tracker's best guess so far (committed or not), then
                # every candidate of this set by its posterior: hypotheses for the scans
                order = np.argsort(-np.asarray(d.probabilities, dtype=float), kind="stable")
                j = int(order[0]) if len(order) else 0
                tentative[r] = [
                    (k, o.time, d.pose.compose(E.inverse()), adjoint_cov(E, cs.covariance[j]))
                ]
                tentative[r] += [
                    (k, o.time, bodies[i], adjoint_cov(E, cs.covariance[i])) for i in order
                ]
            pose = np.full(7, np.nan)
            cluster = (
                same_pose(world, cs.covariance, d.committed)
                if d.locked and d.committed >= 0
                else []
            )
            decided = bool(cluster) and d.probabilities[cluster].sum() >= config.decision_threshold
            if decided:
                j = d.committed
                body = bodies[j]
                kernel = config.kernels.kernel("candidate")
                if pixel_route:
                    factor = None
                elif target.static:  # the target's pose is known: a prior on the observer
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
                if factor is not None:
                    t = max(node_times[r][k], node_times[ti][kt])
                    factors.append((t, factor, "candidate"))
                if not (pixel_route and decided_pose.get(r)):  # pixels: placed once
                    decided_pose.setdefault(r, {})[k] = body
                q = gtsam.Rot3(body.rotation().matrix()).toQuaternion()
                pose = np.r_[body.translation(), q.x(), q.y(), q.z(), q.w()]
            prob = (
                float(d.probabilities[d.committed])
                if d.committed >= 0
                else float(np.max(d.probabilities, initial=0))
            )
            xyz = np.array([b.translation() for b in bodies])
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
                    np.array(d.probabilities, dtype=float),
                    candidates_quat=_quats(bodies),
                )
            )
        if first is not None:
            guessed = r not in decided_pose
            if guessed:
                decided_pose[r] = {first[0]: first[2]}
            alternatives[r] = ([(first[0], body) for body in first[1]], guessed)
    return decisions, decided_pose, placed_via, tentative, alternatives


def mixture_stream(
    run: TeamRun,
    config: GraphConfig,
    timeline: Timeline,
    step_rel: list,
    r: int,
    ti: int,
    obs: list,
    factors: list,
    skips: SkipReport,
    placed_via: dict,
) -> list:
    """A stream whose observer is placed and whose target is not: each set becomes a max-mixture
    (Olson & Agarwal; `factors.mixture.max_mixture_factor`) of BetweenFactorPose3 observer ->
    target, one component per candidate with its covariance, weights from the scores. The
    target's first sighting places it (the candidate whose `body_axis` is nearest its surface
    normal, else the best-scored one); its own motion steps place the rest."""
    node_times, nearest = timeline.node_times, timeline.nearest
    observer, target = run.robots[r], run.robots[ti]
    track = dead_reckoning(observer, step_rel[r], config)
    out = []
    for o in obs:
        k, kt = nearest(r, o.time), nearest(ti, o.time)
        if k < 0 or kt < 0:
            skips.add(
                "no_pose_at_time",
                f"robot {observer.name}: candidate set on {target.name} at {o.time} has no pose "
                f"within the sync tolerance",
            )
            continue
        E = o.body_T_sensor
        seen = o.candidates.poses()  # target_T_sensor
        rel = [E.compose(p.inverse()) for p in seen]  # observer body_T_target
        cand_cov = candidate_covariances(o.candidates, config.tracker.default_sigmas)
        components = [
            gtsam.BetweenFactorPose3(
                pose_key(r, k),
                pose_key(ti, kt),
                rj,
                gtsam.noiseModel.Gaussian.Covariance(adjoint_cov(p, c)),
            )
            for rj, p, c in zip(rel, seen, cand_cov)
        ]
        mixture = (
            max_mixture_factor(components, mixture_weights(o.candidates))
            if len(components) > 1
            else None
        )
        t = max(node_times[r][k], node_times[ti][kt])
        factors.append((t, mixture if mixture is not None else components[0], "candidate"))
        X = track[k][0]
        if ti not in placed_via:
            placed_via[ti] = {kt: (r, k, rel[_upright(target, X, rel, o.candidates)])}
        out.append(
            Decision(
                o.time,
                r,
                ti,
                np.array([X.compose(rj).translation() for rj in rel]),
                0 if mixture is None else -1,
                1.0 if mixture is None else float("nan"),
                np.full(7, np.nan),
                [0] if mixture is None else [],
                None,
                mixture,
                np.stack([rj.matrix() for rj in rel]),
                _quats([X.compose(rj) for rj in rel]),
            )
        )
    return out


def _quats(poses: list) -> np.ndarray:
    """(K,4) x y z w of the poses' rotations."""
    out = np.zeros((len(poses), 4))
    for i, p in enumerate(poses):
        q = p.rotation().toQuaternion()
        out[i] = (q.x(), q.y(), q.z(), q.w())
    return out


def _upright(target, X: gtsam.Pose3, rel: list, candidates) -> int:
    """Index of the candidate that places the target best: with a surface attitude, the one
    whose body axis is nearest the surface normal (seen from the observer's pose X), else the
    best-scored one."""
    if target.surface is None or target.attitude_sigma is None:
        return int(np.argmax(candidates.scores))
    axis = np.asarray(target.body_axis, float)
    up = [X.compose(rj).rotation().matrix() @ axis for rj in rel]
    return int(np.argmax([u @ target.surface.normal for u in up]))
