"""Candidate sets of a placed observer on an unplaced target (seed 003: a camera sees a
teammate's circular base, two candidates): each set a max-mixture the solve chooses."""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np

from graphloc.factors.mixture import candidate_covariances, max_mixture_factor, mixture_weights
from graphloc.keys import pose_key
from graphloc.pipelines.team_graph.config import GraphConfig, adjoint_cov
from graphloc.pipelines.team_graph.decision import SetOutcome, inconsistent, quats, rows_of
from graphloc.pipelines.team_graph.motion import Timeline, dead_reckoning
from graphloc.pipelines.team_graph.section import SectionFactors
from graphloc.run import TeamRun


@dataclass
class MixtureStream:
    """What a max-mixture stream makes: the outcome of every set, its factors and skips, and
    where its first usable sighting places the target ({node: (observer, its node,
    body_T_target)}; None: no set placed it)."""

    outcomes: list = field(default_factory=list)
    made: SectionFactors = field(default_factory=SectionFactors)
    placed: dict | None = None


def mixture_stream(
    run: TeamRun,
    config: GraphConfig,
    timeline: Timeline,
    step_rel: list,
    r: int,
    ti: int,
    obs: list,
) -> MixtureStream:
    """A stream whose observer is placed and whose target is not: each set becomes a max-mixture
    (Olson & Agarwal; `factors.mixture.max_mixture_factor`) of BetweenFactorPose3 observer ->
    target, one component per candidate with its covariance, weights from the scores. The
    target's first sighting places it (the candidate whose `body_axis` is nearest its surface
    normal, else the best-scored one); its own motion steps place the rest."""
    node_times, nearest = timeline.node_times, timeline.nearest
    observer, target = run.robots[r], run.robots[ti]
    track = dead_reckoning(observer, step_rel[r], config)
    result = MixtureStream()
    out, skips = result.outcomes, result.made.skips
    for o in obs:
        if len(o.candidates) == 0:
            skips.add(
                "inconsistent_set",
                f"robot {observer.name}: the marker pixels of {target.name} at {o.time}: no "
                f"pose of its layout passes the pixel chi-square",
                rows_of(o),
            )
            out.append(inconsistent(o, r, ti))
            continue
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
        result.made.factors.append(
            (t, mixture if mixture is not None else components[0], "candidate")
        )
        X = track[k][0]
        if result.placed is None:
            result.placed = {kt: (r, k, rel[_upright(target, X, rel, o.candidates)])}
        out.append(
            SetOutcome(
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
                quats([X.compose(rj) for rj in rel]),
                status="decided" if mixture is None else "undecided",
                measured=np.stack([p.matrix() for p in seen]),
                measured_cov=cand_cov,
                body_T_sensor=E.matrix(),
            )
        )
    return result


def _upright(target, X: gtsam.Pose3, rel: list, candidates) -> int:
    """Index of the candidate that places the target best: with a surface attitude, the one
    whose body axis is nearest the surface normal (seen from the observer's pose X), else the
    best-scored one."""
    if target.surface is None or target.attitude_sigma is None:
        return int(np.argmax(candidates.scores))
    axis = np.asarray(target.body_axis, float)
    up = [X.compose(rj).rotation().matrix() @ axis for rj in rel]
    return int(np.argmax([u @ target.surface.normal for u in up]))
