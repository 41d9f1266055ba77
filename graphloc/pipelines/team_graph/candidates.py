"""Candidate sets (P3P, seed 000 / 001 / 004) of a placed target -> factors: per (observer,
target) stream one `HypothesisTracker` decides causally (`StreamTracker`, seed 000 Sec. V),
and `set_factors` makes the decided sets robust priors / between factors, or a pixel
stream's marker pixels projection factors. `SetOutcome`: the team graph's record of one
candidate set (not `seams.Decision`, one tracker update), with the helpers the tracked and
max-mixture (`mixtures`) streams share."""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.mixture import candidate_covariances
from graphloc.factors.robust import robust_noise
from graphloc.hypotheses import HypothesisTracker
from graphloc.textio import SkipReport
from graphloc.keys import pose_key
from graphloc.pipelines.team_graph.camera import marker_factors, moving_marker_factors
from graphloc.pipelines.team_graph.config import GraphConfig, adjoint_cov
from graphloc.pipelines.team_graph.motion import compose_steps, dead_reckoning
from graphloc.pipelines.team_graph.graph import SectionFactors
from graphloc.run import TeamRun
from graphloc.seams import Decision, Odometry


@dataclass
class SetOutcome:
    """What happened to one candidate set: where each candidate puts the observer's body, the
    committed candidate (-1: none), its posterior (else the largest) and pose (x y z qx qy qz
    qw), the candidates of the committed one's pose (`same_pose`); status "decided",
    "undecided" or "inconsistent"; measured / measured_cov / body_T_sensor: what the truth
    judges a decision by. A max-mixture set is chosen by the solve (`passes.choose_mixtures`)."""

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
    status: str = "undecided"
    measured: np.ndarray | None = None  # (K,4,4) target_T_sensor per candidate
    measured_cov: np.ndarray | None = None  # (K,6,6) their covariances
    body_T_sensor: np.ndarray | None = None  # (4,4)


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


def inconsistent(o, r: int, ti: int) -> SetOutcome:
    """The record of a set no candidate of which passed the pixel chi-square."""
    return SetOutcome(
        o.time,
        r,
        ti,
        np.zeros((0, 3)),
        -1,
        0.0,
        np.full(7, np.nan),
        [],
        np.zeros(0),
        status="inconsistent",
        body_T_sensor=o.body_T_sensor.matrix(),
    )


def quats(poses: list) -> np.ndarray:
    """(K,4) x y z w of the poses' rotations."""
    out = np.zeros((len(poses), 4))
    for i, p in enumerate(poses):
        q = p.rotation().toQuaternion()
        out[i] = (q.x(), q.y(), q.z(), q.w())
    return out


def rows_of(observation) -> int:
    """The log rows a candidate set was made of: its marker pixels, else one (a `candidates`
    set, an ellipse)."""
    return len(observation.pixels.markers) if observation.pixels is not None else 1


@dataclass(frozen=True)
class TrackedSet:
    """One set of a tracked stream as the tracker saw it: its index, observation, observer and
    target nodes k / kt, each candidate as target_T_sensor (`seen`, `measured_cov`) and as the
    observer's world_T_body (`bodies`, `covariance` with the target's uncertainty), the tracker's
    update and whether it decided the set."""

    index: int
    observation: object
    k: int
    kt: int
    seen: list
    measured_cov: np.ndarray
    bodies: list
    covariance: np.ndarray
    update: Decision  # the tracker's
    decided: bool


@dataclass
class StreamDecisions:
    """What the tracker made of one (observer, target) stream: the sets it saw, what became of
    every set (`SetOutcome`, inconsistent ones included), the sets it skipped, and the latest
    best guess with every candidate of that set by posterior ((node, time, body pose, 6x6
    covariance) each; None: no guess)."""

    robot: int
    target: int
    pixel_route: bool
    sets: list = field(default_factory=list)
    outcomes: list = field(default_factory=list)
    skips: SkipReport = field(default_factory=SkipReport)
    tentative: list | None = None


class StreamTracker:
    """One (observer r, placed target ti) stream's HypothesisTracker fed one set at a time (`add`),
    causally; `out`: its `StreamDecisions`. A set without a (new) pose is a counted
    `no_pose_at_time`, an inconsistent one (no candidate passed the pixel chi-square) an
    `inconsistent_set` never decided."""

    def __init__(self, run: TeamRun, config: GraphConfig, r: int, ti: int, pixel_route: bool):
        self.run, self.config, self.r, self.ti = run, config, r, ti
        self.out = StreamDecisions(r, ti, pixel_route)
        self.tracker = HypothesisTracker(config.tracker)
        self.prev = None
        self.target_track: list | None = None

    def add(self, n: int, o, k: int, kt: int, step_rel: list):
        """Set n (`o`, at observer node k and target node kt, -1: none) through the tracker;
        its `TrackedSet` (None: skipped or inconsistent)."""
        run, config, r, ti, out = self.run, self.config, self.r, self.ti, self.out
        observer, target = run.robots[r], run.robots[ti]
        prev = self.prev
        if len(o.candidates) == 0:
            meta = o.candidates.meta
            out.skips.add(
                "inconsistent_set",
                f"robot {observer.name}: the marker pixels of {target.name} at "
                f"{o.time}: no pose of its layout passes the pixel chi-square (least "
                f"{meta.get('chi2_min', float('nan')):.1f} > gate {meta.get('gate', 0):.1f})",
                rows_of(o),
            )
            out.outcomes.append(inconsistent(o, r, ti))
            return None
        if k < 0 or (prev is not None and k == prev):
            out.skips.add(
                "no_pose_at_time",
                f"robot {observer.name}: candidate set at {o.time} has no "
                f"(new) pose within the sync tolerance",
            )
            return None
        if kt < 0:
            out.skips.add(
                "no_pose_at_time",
                f"robot {target.name}: seen at {o.time} with no pose within the sync tolerance",
            )
            return None
        if self.target_track is None or kt >= len(self.target_track):
            self.target_track = dead_reckoning(
                target, step_rel[ti][: kt + 1], config, self.target_track
            )
        E = o.body_T_sensor
        X_t, P_t = self.target_track[kt]
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
            observer.name,
            target.name,
            o.candidates.source,
            o.candidates.meta,
            cov,
        )
        odo = None
        if prev is not None:
            rel, odo_cov = compose_steps(step_rel[r], prev, k, config)
            odo = Odometry(E.inverse().compose(rel).compose(E), adjoint_cov(E.inverse(), odo_cov))
        d = self.tracker.update(cs, odo)
        self.prev = k
        if d.pose is not None:  # the tracker's best guess so far (committed or not), then
            # every candidate of this set by its posterior: hypotheses for the scans
            order = np.argsort(-np.asarray(d.probabilities, dtype=float), kind="stable")
            j = int(order[0]) if len(order) else 0
            out.tentative = [
                (k, o.time, d.pose.compose(E.inverse()), adjoint_cov(E, cs.covariance[j]))
            ]
            out.tentative += [
                (k, o.time, bodies[c], adjoint_cov(E, cs.covariance[c])) for c in order
            ]
        cluster = (
            same_pose(world, cs.covariance, d.committed) if d.locked and d.committed >= 0 else []
        )
        decided = bool(cluster) and d.probabilities[cluster].sum() >= config.decision_threshold
        out.sets.append(TrackedSet(n, o, k, kt, seen, cand_cov, bodies, cov, d, decided))
        out.outcomes.append(_outcome(o, r, ti, out.sets[-1], cluster))
        return out.sets[-1]


def _outcome(o, r: int, ti: int, s: TrackedSet, cluster: list) -> SetOutcome:
    """The record of a set the tracker saw."""
    d = s.update
    pose = np.full(7, np.nan)
    if s.decided:
        body = s.bodies[d.committed]
        q = gtsam.Rot3(body.rotation().matrix()).toQuaternion()
        pose = np.r_[body.translation(), q.x(), q.y(), q.z(), q.w()]
    prob = (
        float(d.probabilities[d.committed])
        if d.committed >= 0
        else float(np.max(d.probabilities, initial=0))
    )
    return SetOutcome(
        o.time,
        r,
        ti,
        np.array([b.translation() for b in s.bodies]),
        int(d.committed) if s.decided else -1,
        prob,
        pose,
        cluster if s.decided else [],
        np.array(d.probabilities, dtype=float),
        candidates_quat=quats(s.bodies),
        status="decided" if s.decided else "undecided",
        measured=homogeneous(o.candidates.R, o.candidates.t),
        measured_cov=s.measured_cov,
        body_T_sensor=o.body_T_sensor.matrix(),
    )


def homogeneous(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(K,4,4) [R t; 0 1] of rotations (K,3,3) and translations (K,3)."""
    out = np.zeros((len(R), 4, 4))
    out[:, :3, :3], out[:, :3, 3], out[:, 3, 3] = R, t, 1.0
    return out


def set_factors(
    run: TeamRun,
    config: GraphConfig,
    node_times: list,
    s: TrackedSet,
    pixel_route: bool,
    marker_points: dict,
) -> SectionFactors:
    """The factors of one tracked set: a pixel stream's marker pixels as projection factors,
    else a decided set's robust prior (static target) or between factor (moving target);
    `marker_points`: the static markers made before, so a point enters once."""
    o, k, kt, E = s.observation, s.k, s.kt, s.observation.body_T_sensor
    r, ti = o.robot, o.target
    target = run.robots[ti]
    t = max(node_times[r][k], node_times[ti][kt])
    if pixel_route and target.static:
        return marker_factors(run, config, r, k, t, o, E, marker_points)
    if pixel_route:
        return moving_marker_factors(run, config, r, k, kt, s.index, t, o)
    out = SectionFactors()
    if not s.decided:
        return out
    kernel = config.kernels.kernel("candidate")
    j = s.update.committed
    if target.static:  # the target's pose is known: a prior on the observer
        noise = robust_noise(
            gtsam.noiseModel.Gaussian.Covariance(adjoint_cov(E, s.covariance[j])), kernel
        )
        factor = gtsam.PriorFactorPose3(pose_key(r, k), s.bodies[j], noise)
    else:
        # observer_T_target = E target_T_sensor^-1, covariance moved to the target's side
        noise = robust_noise(
            gtsam.noiseModel.Gaussian.Covariance(adjoint_cov(s.seen[j], s.measured_cov[j])),
            kernel,
        )
        factor = gtsam.BetweenFactorPose3(
            pose_key(r, k), pose_key(ti, kt), E.compose(s.seen[j].inverse()), noise
        )
    out.factors.append((t, factor, "candidate"))
    return out
