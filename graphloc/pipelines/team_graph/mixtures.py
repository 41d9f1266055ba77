"""Candidate sets of a placed observer on an unplaced target (seed 003: a camera sees a
teammate's circular base, two candidates): each set a max-mixture the solve chooses, set by set
(`MixtureTracker`, fed by `live.event_camera`)."""

from __future__ import annotations


import gtsam
import numpy as np

from graphloc.factors.mixture import candidate_covariances, max_mixture_factor, mixture_weights
from graphloc.keys import pose_key
from graphloc.pipelines.team_graph.config import GraphConfig, adjoint_cov
from graphloc.pipelines.team_graph.candidates import SetOutcome, inconsistent, quats, rows_of
from graphloc.pipelines.team_graph.motion import dead_reckoning
from graphloc.pipelines.team_graph.graph import SectionFactors
from graphloc.run import TeamRun


class MixtureTracker:
    """One (placed observer r, unplaced target ti) stream fed one set at a time (`add`): each set a
    max-mixture (Olson & Agarwal) of between factors observer -> target, one per candidate; the
    first usable sighting places the target (`placed`: {node: (observer, its node, body_T_target)},
    the candidate nearest upright). `outcomes`: every set's; `made`: factors and skips."""

    def __init__(self, run: TeamRun, config: GraphConfig, r: int, ti: int):
        self.run, self.config, self.r, self.ti = run, config, r, ti
        self.outcomes: list = []
        self.made = SectionFactors()
        self.placed: dict | None = None
        self.track: list = []  # the observer's dead reckoning, grown as sets need it
        self.pending: list = []  # factors made by the last `add`, their times not set yet

    def add(self, o, k: int, kt: int, steps: list):
        """Set `o` at observer node k and target node kt (-1: none); `steps`: the observer's
        step_rel, known up to k. Returns the set's graph item (a max-mixture, or a
        BetweenFactorPose3 for a single candidate; None: skipped), made into
        (time, factor, "candidate") by `factor_times`."""
        run, config, r, ti = self.run, self.config, self.r, self.ti
        observer, target = run.robots[r], run.robots[ti]
        skips = self.made.skips
        if len(o.candidates) == 0:
            skips.add(
                "inconsistent_set",
                f"robot {observer.name}: the marker pixels of {target.name} at {o.time}: no "
                f"pose of its layout passes the pixel chi-square",
                rows_of(o),
            )
            self.outcomes.append(inconsistent(o, r, ti))
            return None
        if k < 0 or kt < 0:
            skips.add(
                "no_pose_at_time",
                f"robot {observer.name}: candidate set on {target.name} at {o.time} has no pose "
                f"within the sync tolerance",
            )
            return None
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
        factor = mixture if mixture is not None else components[0]
        self.pending.append((k, kt, factor))
        if len(self.track) <= k:  # the observer's dead reckoning, grown up to k
            self.track = dead_reckoning(observer, steps[: k + 1], config, self.track)
        X = self.track[k][0]
        if self.placed is None:
            self.placed = {kt: (r, k, rel[_upright(target, X, rel, o.candidates)])}
        self.outcomes.append(
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
        return factor

    def factor_times(self, node_times: list) -> list:
        """The factors of the sets added since the last call as (time, factor, "candidate"),
        each at the newer of its two poses' times (appended to `made.factors` too)."""
        made = [
            (max(node_times[self.r][k], node_times[self.ti][kt]), f, "candidate")
            for k, kt, f in self.pending
        ]
        self.pending = []
        self.made.factors += made
        return made


def _upright(target, X: gtsam.Pose3, rel: list, candidates) -> int:
    """Index of the candidate that places the target best: with a surface attitude, the one
    whose body axis is nearest the surface normal (seen from the observer's pose X), else the
    best-scored one."""
    if target.surface is None or target.attitude_sigma is None:
        return int(np.argmax(candidates.scores))
    axis = np.asarray(target.body_axis, float)
    up = [X.compose(rj).rotation().matrix() @ axis for rj in rel]
    return int(np.argmax([u @ target.surface.normal for u in up]))
