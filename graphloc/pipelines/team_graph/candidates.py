"""Candidate sets (P3P, seed 000 / 001 / 004) -> factors: one HypothesisTracker per
(observer, target) stream decides causally; a decided candidate becomes one robust factor, or,
where the set's marker pixels are known and the target is static, the pixels themselves enter
(`camera.marker_factors`) and the candidates place the observer."""

from __future__ import annotations

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.candidates import CandidateSet
from graphloc.factors.mixture import candidate_covariances
from graphloc.factors.robust import robust_noise
from graphloc.hypotheses import HypothesisTracker
from graphloc.io import SkipReport
from graphloc.keys import pose_key
from graphloc.pipelines.team_graph.camera import marker_factors, moving_marker_factors
from graphloc.pipelines.team_graph.config import GraphConfig, adjoint_cov
from graphloc.pipelines.team_graph.decision import (
    Decision,
    inconsistent,
    quats,
    rows_of,
    same_pose,
)
from graphloc.pipelines.team_graph.mixtures import mixture_stream
from graphloc.pipelines.team_graph.motion import Timeline, compose_steps, dead_reckoning
from graphloc.run import TeamRun
from graphloc.seams import Odometry


def candidate_factors(
    run: TeamRun,
    config: GraphConfig,
    timeline: Timeline,
    step_rel: list,
    factors: list,
    skips: SkipReport,
    marker_points: dict,
    frame_points: list,
    progress: bool = False,
) -> tuple[list, dict, dict, dict, dict]:
    """Every candidate set as factors, by one rule per (observer, target) stream:
    - the target is placed (known initial pose): the observer is placed through it; one
      HypothesisTracker decides causally. When the sets carry their marker pixels, the pixels
      become projection factors (`camera.marker_factors` on a static target's marker points,
      `camera.moving_marker_factors` on both poses of a moving one; a decided candidate would
      count them twice) and the observer is placed at its first decided set, or, if the
      tracker never decides, at the stream's first set by the tracker's guess there; every
      candidate of that set is an alternative placement the solve also starts from
      (`alternatives`). Without pixels a decided candidate becomes one robust factor;
    - the target is not placed but the observer is (e.g. seed 003: a camera sees a teammate's
      base, two circle candidates): the target is placed through the observer and each set
      enters as a max-mixture of its candidates (`mixture_stream`), chosen by the solve.
    An inconsistent set (no candidate passed the pixel chi-square, `vision.marker_poses`) is
    never decided and its pixels never enter: a Decision with status "inconsistent" and a
    counted skip `inconsistent_set`.
    Returns the decisions, the decided observer poses (robot -> {node: Pose3}), the targets
    placed through an observer (robot -> {node: (observer, node, body_T_target)}) and each
    tracked observer's latest best guess, decided or not (robot -> (node, time, body pose,
    6x6 covariance; the hint of the inter-robot scan registration, `team_graph.scans`) and the
    alternative placements of pixel streams (robot -> ([(node, body Pose3) per candidate],
    placed by the tracker's guess, never decided)); a static target's marker points land in
    `marker_points` (key -> world position), a moving target's per-set points in
    `frame_points` ((key, target, node, body-frame position) each)."""
    node_times, nearest = timeline.node_times, timeline.nearest
    decisions, decided_pose, placed_via, tentative, alternatives = [], {}, {}, {}, {}
    streams: dict = {}
    for n, o in enumerate(run.observations):
        streams.setdefault((o.robot, o.target), []).append((n, o))
    for (r, ti), obs in tqdm(
        streams.items(), desc="deciding candidate sets", disable=not progress, unit="stream"
    ):
        target = run.robots[ti]
        if target.initial_pose is None and run.robots[r].initial_pose is not None:
            decisions += mixture_stream(
                run,
                config,
                timeline,
                step_rel,
                r,
                ti,
                [o for _, o in obs],
                factors,
                skips,
                placed_via,
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
        pixel_route = all(o.pixels is not None for _, o in obs)
        ks = [nearest(r, o.time) for _, o in obs]
        kts = [nearest(ti, o.time) for _, o in obs]
        offsets: dict = {}
        if pixel_route:  # each robot's motion between its pose and the set's time
            ok = [i for i in range(len(obs)) if ks[i] >= 0 and kts[i] >= 0]
            times = [obs[i][1].time for i in ok]
            mine = timeline.offsets(r, [ks[i] for i in ok], times)
            theirs = timeline.offsets(ti, [kts[i] for i in ok], times)
            offsets = {i: pair for i, pair in zip(ok, zip(mine, theirs))}
        first = None  # pixel route: (node, body pose per candidate, the tracker's guess)
        for i, (n, o) in enumerate(obs):
            k, kt = ks[i], kts[i]
            if len(o.candidates) == 0:
                meta = o.candidates.meta
                skips.add(
                    "inconsistent_set",
                    f"robot {run.robots[r].name}: the marker pixels of {target.name} at "
                    f"{o.time}: no pose of its layout passes the pixel chi-square (least "
                    f"{meta.get('chi2_min', float('nan')):.1f} > gate {meta.get('gate', 0):.1f})",
                    rows_of(o),
                )
                decisions.append(inconsistent(o, r, ti))
                continue
            if k < 0 or (prev is not None and k == prev):
                skips.add(
                    "no_pose_at_time",
                    f"robot {run.robots[r].name}: candidate set at {o.time} has no "
                    f"(new) pose within the sync tolerance",
                )
                continue
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
                t = max(node_times[r][k], node_times[ti][kt])
                mine, theirs = offsets[i]
                if target.static:
                    marker_factors(
                        run, config, r, k, t, o, mine.compose(E), factors, marker_points, skips
                    )
                else:
                    moving_marker_factors(
                        run,
                        config,
                        r,
                        k,
                        kt,
                        n,
                        t,
                        o,
                        (mine, theirs),
                        factors,
                        frame_points,
                        skips,
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
                    (k, o.time, bodies[c], adjoint_cov(E, cs.covariance[c])) for c in order
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
                    candidates_quat=quats(bodies),
                    status="decided" if decided else "undecided",
                    measured=np.stack([p.matrix() for p in seen]),
                    measured_cov=cand_cov,
                    body_T_sensor=E.matrix(),
                )
            )
        if first is not None:
            guessed = r not in decided_pose
            if guessed:
                decided_pose[r] = {first[0]: first[2]}
            alternatives[r] = ([(first[0], body) for body in first[1]], guessed)
    return decisions, decided_pose, placed_via, tentative, alternatives
