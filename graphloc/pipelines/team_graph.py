"""One run, one graph: every table of a heterogeneous team's run (`graphloc.run.TeamRun`) as
factors on SE(3) poses, solved in batch (Levenberg-Marquardt) or online (iSAM2) through one
`graphloc.session.Session`. The function behind `graphloc smooth` and `graphloc online`.

Poses: robot r's k-th pose `pose_key(r, k)` (gtsam.Pose3, world_T_body). A robot's pose times:
- wheel odometry (planar velocities): a grid start + k * keyframe_dt, the steps integrated
  exactly along arcs (`factors.odometry.integrate_unicycle`), measurements re-expressed in the
  body frame at the grid time (only the target's motion over <= dt/2 is neglected);
- relative poses (2D or 3D tables): the tables' own time stamps;
- a static robot: one pose; any other robot: the times it observes or is observed.
A measurement joins the pose nearest its time (within dt/2 on a grid, `sync_tolerance`
otherwise) or is counted as a skip.

Factors: prior on each known initial pose; BetweenFactorPose3 per odometry / relative-pose step
(planar robots: out-of-plane directions held to `graphloc.run.PLANAR_SIGMA`); the surface a
climbing robot moves on (`factors.surface`); range-bearing (BearingRangeFactor3D /
BearingRangeFactorPose3), bearing (`factors.bearing.bearing_factor` with the sensor extrinsics,
BearingFactor3D to landmarks), range (`factors.bearing.range_factor`, RangeFactor3D); known
landmarks as one prior-pinned anchor per observation (each iSAM2 update stays local).

Candidate sets (P3P, seed 000 / 001 / 004) enter through one route: per (observer, target)
stream a `graphloc.hypotheses.HypothesisTracker` (seed 000 Sec. V's belief over the candidates,
seed 004's particle filter) decides causally, frame by frame, with the observer's odometry
between frames, each set seen in the world through the target's pose (static: known; moving:
its odometry from its initial pose, that uncertainty added to the candidates'). A decided
candidate becomes a robust factor: a prior on the observer (static target) or a between factor
observer -> target. Decisions are causal, so batch and online solve the same factors. A robot
with no known initial pose enters the online graph at its first decided set (before that
nothing anchors it).
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.candidates import CandidateSet
from graphloc.factors.bearing import bearing_factor, range_factor
from graphloc.factors.mixture import candidate_covariances
from graphloc.factors.odometry import VelocityNoise, integrate_unicycle
from graphloc.factors.range_bearing import landmark_factor_3d, robot_factor_3d
from graphloc.factors.robust import Kernel, KernelPolicy, robust_noise
from graphloc.factors.surface import surface_factors
from graphloc.hypotheses import HypothesisTracker, TrackerConfig
from graphloc.io import SkipReport
from graphloc.keys import decode, landmark_key, pose_key
from graphloc.run import TeamRun, planar_covariance, pose_from_planar
from graphloc.seams import Odometry
from graphloc.session import Session, SessionConfig

COARSE_PRECISION = 0.1  # [m, rad] scale of a run without pose measurements (wheels, range-bearing)
FINE_PRECISION = 0.002  # the finest precision iSAM2's thresholds follow
ANCHOR_BASE = (
    100_000_000  # landmark_key(ANCHOR_BASE + j): j-th per-observation anchor of a known landmark
)


DEFAULT_LAG = 20.0  # [s] online fixed-lag window (scripts/bench_scale.py measures the choice)


@dataclass(frozen=True)
class GraphConfig:
    """keyframe_dt [s]: pose grid of wheel-odometry robots; sync_tolerance [s]: how far from a
    pose a measurement of an event-clocked robot may be; which measurements to use; robust
    kernels by factor type (odometry, landmark, inter_robot, candidate); initial_sigma (rot
    [rad], trans [m]) of initial-pose priors a robot does not state; static_sigma of static
    robots' poses; surface_sigma [m]: distance of a climbing robot from its surface;
    landmark_prior_floor [m]; unknown_motion_sigma (rot, trans) between frames of a robot with
    no odometry; tracker: the HypothesisTracker deciding candidate sets; decision_threshold: a
    set is decided -- its candidate enters the graph -- when the tracker has committed to a
    track and that track's candidate in the set, with the candidates that are the same pose
    within their covariances (`_same_pose`), has at least this posterior; session settings
    (iSAM2 thresholds None: set from the run's precision, `run_precision`)."""

    keyframe_dt: float = 0.25
    sync_tolerance: float = 0.02
    use_landmarks: bool = True
    use_inter_robot: bool = True
    landmark_priors: bool = True
    anchor_known_landmarks: bool = True
    kernels: KernelPolicy = KernelPolicy(
        {
            "landmark": Kernel("cauchy", 2.0),
            "inter_robot": Kernel("cauchy", 2.0),
            "candidate": Kernel("cauchy", 1.0),
        }
    )
    velocity_noise: VelocityNoise = VelocityNoise(density_v=0.01, density_w=0.05)
    initial_sigma: tuple = (0.02, 0.05)
    static_sigma: tuple = (1e-4, 1e-4)
    surface_sigma: float = 0.005
    landmark_prior_floor: float = 0.01
    unknown_motion_sigma: tuple = (3.0, 100.0)
    tracker: TrackerConfig = TrackerConfig()
    decision_threshold: float = 0.8  # see the docstring
    downweight_threshold: float = 0.1
    relinearize_threshold: float | None = None
    relinearize_skip: int = 10
    wildfire_threshold: float | None = None
    extra_updates: int | None = None
    lm_max_iterations: int = 100
    lag: float | None = None  # online: fixed-lag window [s] (None / 0: full smoothing)

    def __post_init__(self):
        if self.lag is not None and not (np.isfinite(self.lag) and self.lag >= 0):
            raise ValueError(f"GraphConfig.lag must be None or finite >= 0, got {self.lag}")
        if not 0.5 <= self.decision_threshold < 1.0:
            raise ValueError(
                f"GraphConfig.decision_threshold must be in [0.5, 1), got {self.decision_threshold}"
            )
        for name in ("keyframe_dt", "sync_tolerance", "surface_sigma", "landmark_prior_floor"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"GraphConfig.{name} must be finite > 0, got {v}")
        for name in ("initial_sigma", "static_sigma", "unknown_motion_sigma"):
            v = getattr(self, name)
            if len(v) != 2 or not all(np.isfinite(s) and s > 0 for s in v):
                raise ValueError(f"GraphConfig.{name} must be 2 numbers > 0 (rot, trans), got {v}")

    def session_config(self, mode: str, precision: float = COARSE_PRECISION) -> SessionConfig:
        """Session settings; iSAM2's settings, unless set, follow the run's `precision` (see
        `run_precision`): relinearize when a variable's update exceeds half of it, stop the
        back-substitution where the solution changes by less than a tenth of it, and on
        camera-precise runs two extra iSAM2 iterations per step (robust candidate factors need
        iterations to reweight; such runs have few steps)."""
        relin = (
            self.relinearize_threshold
            if self.relinearize_threshold is not None
            else 0.5 * precision
        )
        wildfire = (
            self.wildfire_threshold if self.wildfire_threshold is not None else 0.1 * precision
        )
        extra = (
            self.extra_updates
            if self.extra_updates is not None
            else (2 if precision < COARSE_PRECISION else 0)
        )
        return SessionConfig(
            mode=mode,
            lm_max_iterations=self.lm_max_iterations,
            relinearize_threshold=relin,
            relinearize_skip=self.relinearize_skip,
            wildfire_threshold=wildfire,
            extra_updates=extra,
            partial_relinearization_check=True,
        )


def _cov(sig: tuple) -> np.ndarray:
    return np.diag([sig[0] ** 2] * 3 + [sig[1] ** 2] * 3)


def _adjoint_cov(T: gtsam.Pose3, cov: np.ndarray) -> np.ndarray:
    A = T.AdjointMap()
    return A @ cov @ A.T


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


@dataclass
class TeamGraph:
    """The run as one graph, step by step: steps[i] = (time, [(factor, type), ...]); node
    times per robot; dead-reckoning / decided initial values; factor type counts."""

    run: TeamRun
    config: GraphConfig
    node_times: list
    initial: dict  # key -> Pose3 (initial guess)
    steps: list
    factor_types: list
    decisions: list
    anchored_from: dict  # robot -> first node time the online graph may hold it
    step_rel: (
        list  # per robot (relative Pose3 from node k-1, covariance) for k >= 1 (None: unknown)
    )
    counts: dict = field(default_factory=dict)
    skips: SkipReport = field(default_factory=SkipReport)
    precision: float = COARSE_PRECISION  # run_precision(run)


def _node_times(run: TeamRun, config: GraphConfig) -> list:
    out = []
    for r, robot in enumerate(run.robots):
        vel = run.velocity[r]
        if robot.static:
            times = np.array([run.start_time])
        elif len(vel):
            end = vel[-1, 0]
            n = int(np.floor((end - run.start_time) / config.keyframe_dt + 1e-9)) + 1
            times = run.start_time + config.keyframe_dt * np.arange(max(n, 1))
        else:
            stamps = [t for m in run.motions if m.robot == r for t in (m.t0, m.t1)]
            if not stamps:
                stamps = [p.time for p in run.points if r in (p.robot, p.target)]
                stamps += [o.time for o in run.observations if r in (o.robot, o.target)]
            times = np.unique(np.round(np.array(stamps, dtype=float), 9))
        out.append(times)
    return out


def velocity_noise(run: TeamRun, r: int, config: GraphConfig) -> VelocityNoise:
    """Wheel-odometry noise densities of robot r: its odometry sensor's params (density_v
    [m/sqrt(s)], density_w [rad/sqrt(s)], `factors.odometry.VelocityNoise`) where given, else
    the config's."""
    base = config.velocity_noise
    for _, params in run.robots[r].sensors.values():
        if "density_v" in params or "density_w" in params:
            return VelocityNoise(
                density_v=float(params.get("density_v", base.density_v)),
                density_w=float(params.get("density_w", base.density_w)),
            )
    return base


def _velocity_steps(run: TeamRun, r: int, times: np.ndarray, config: GraphConfig) -> list:
    od = run.velocity[r]
    integ = integrate_unicycle(od[:, 0], od[:, 1], od[:, 2], times, velocity_noise(run, r, config))
    return [None] + [
        (pose_from_planar(*d), planar_covariance(c))
        for d, c in zip(integ.deltas, integ.covariances)
    ]


def build_graph(
    run: TeamRun, config: GraphConfig = GraphConfig(), progress: bool = False
) -> TeamGraph:
    """Every usable row of `run` as a factor, grouped in time steps; candidate sets decided by
    one HypothesisTracker per (observer, static target) stream."""
    skips = SkipReport()
    skips.merge(run.skips)
    R = len(run.robots)
    node_times = _node_times(run, config)
    factors: list = []  # (time of newest node, factor, type)

    def nearest(r: int, t: float) -> int:
        times = node_times[r]
        if run.robots[r].static:
            return 0
        if not len(times):
            return -1
        i = int(np.clip(np.searchsorted(times, t), 1, len(times) - 1)) if len(times) > 1 else 0
        if i > 0 and abs(times[i - 1] - t) <= abs(times[i] - t):
            i -= 1
        tol = config.keyframe_dt / 2 + 1e-9 if len(run.velocity[r]) else config.sync_tolerance
        return i if abs(times[i] - t) <= tol else -1

    # --- motion: steps between consecutive nodes ---
    step_rel = []
    for r, robot in enumerate(run.robots):
        times = node_times[r]
        steps = [None] * len(times)
        if len(run.velocity[r]) and not robot.static:
            steps = _velocity_steps(run, r, times, config)
            for k in range(1, len(times)):
                factors.append((times[k], _between(r, k - 1, k, *steps[k], config), "odometry"))
        for m in (m for m in run.motions if m.robot == r):
            k0, k1 = nearest(r, m.t0), nearest(r, m.t1)
            if k0 < 0 or k1 < 0 or k0 == k1:
                skips.add(
                    "no_pose_at_time",
                    f"robot {robot.name}: relative pose {m.t0}->{m.t1} has no poses",
                )
                continue
            factors.append(
                (
                    times[max(k0, k1)],
                    _between(r, k0, k1, m.relative, m.covariance, config),
                    "odometry",
                )
            )
            if k1 == k0 + 1 and steps[k1] is None:
                steps[k1] = (m.relative, m.covariance)
        step_rel.append(steps)

    # --- anchors: priors and surfaces ---
    for r, robot in enumerate(run.robots):
        if robot.initial_pose is not None and len(node_times[r]):
            sig = (
                config.static_sigma
                if robot.static
                else (robot.initial_sigma or config.initial_sigma)
            )
            factors.append(
                (
                    node_times[r][0],
                    gtsam.PriorFactorPose3(
                        pose_key(r, 0),
                        robot.initial_pose,
                        gtsam.noiseModel.Gaussian.Covariance(_cov(sig)),
                    ),
                    "prior",
                )
            )
        if robot.surface is not None:
            for k, t in enumerate(node_times[r]):
                for f in surface_factors(
                    pose_key(r, k), robot.surface, config.surface_sigma, attitude_sigma=None
                ):
                    factors.append((t, f, "surface"))

    # --- point measurements ---
    lm_prior = {}
    if config.landmark_priors and run.landmarks_known:
        lm_prior = {
            int(i): (p, np.maximum(s, config.landmark_prior_floor))
            for i, p, s in zip(run.landmark_ids, run.landmark_xyz, run.landmark_sigma)
        }
    landmark_guess: dict = {}
    n_anchor = 0
    corrected = _corrected_range_bearings(run, node_times, config)
    excluded = 0  # measurements the options leave out (not a data problem: counted, not skipped)
    for i, m in enumerate(run.points):
        is_lm = m.target < 0
        if (is_lm and not config.use_landmarks) or (not is_lm and not config.use_inter_robot):
            excluded += 1
            continue
        k = nearest(m.robot, m.time)
        kt = -1 if is_lm else nearest(m.target, m.time)
        if k < 0 or (not is_lm and kt < 0):
            skips.add(
                "no_pose_at_time",
                f"robot {run.robots[m.robot].name}: {m.kind} at {m.time} has no pose "
                f"within the sync tolerance",
            )
            continue
        key = pose_key(m.robot, k)
        direction, rng = corrected.get(i, (m.direction, m.range))
        E = m.body_T_sensor
        t_new = max(node_times[m.robot][k], -np.inf if is_lm else node_times[m.target][kt])
        kernel = config.kernels.kernel("landmark" if is_lm else "inter_robot")
        if m.kind == "range_bearing" and i not in corrected:
            p = E.transformFrom(direction * rng)
            direction, rng = p / np.linalg.norm(p), float(np.linalg.norm(p))
        if is_lm:
            lkey, prior = _landmark_key(m.landmark, lm_prior, config, n_anchor)
            if lkey is None:
                skips.add("unknown_landmark", f"landmark {m.landmark} is not in the landmark table")
                continue
            if lkey not in landmark_guess:
                guess = prior[0] if prior is not None else None
                if guess is None and np.isfinite(rng):
                    guess = ("from", m.robot, k, direction, rng)
                if guess is None:
                    skips.add(
                        "landmark_without_position",
                        f"landmark {m.landmark}: first seen by a bearing only",
                    )
                    continue
                landmark_guess[lkey] = guess
                if prior is not None:
                    factors.append(
                        (
                            t_new,
                            gtsam.PriorFactorPoint3(
                                lkey,
                                np.asarray(prior[0], float),
                                gtsam.noiseModel.Diagonal.Sigmas(prior[1]),
                            ),
                            "landmark_prior",
                        )
                    )
            if lkey != landmark_key(m.landmark):
                n_anchor += 1
            factors.append(
                (t_new, _point_factor(m, key, lkey, direction, rng, kernel, E), "landmark")
            )
        else:
            factors.append(
                (
                    t_new,
                    _robot_factor(m, key, pose_key(m.target, kt), direction, rng, kernel, E),
                    "inter_robot",
                )
            )

    # --- candidate sets: one tracker per (observer, target) stream ---
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
        target_track = _dead_reckoning(target, step_rel[ti], config)
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
            cov = cand_cov + np.stack([_adjoint_cov(p.inverse(), P_t) for p in seen])
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
                rel, cov = _compose_steps(step_rel[r], prev, k, config)
                odo = Odometry(E.inverse().compose(rel).compose(E), _adjoint_cov(E.inverse(), cov))
            d = tracker.update(cs, odo)
            prev = k
            pose = np.full(7, np.nan)
            cluster = (
                _same_pose(world, cs.covariance, d.committed)
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
                        gtsam.noiseModel.Gaussian.Covariance(_adjoint_cov(E, cs.covariance[j])),
                        kernel,
                    )
                    factor = gtsam.PriorFactorPose3(pose_key(r, k), body, noise)
                else:
                    # observer_T_target = E target_T_sensor^-1, covariance moved to the target's
                    # side
                    noise = robust_noise(
                        gtsam.noiseModel.Gaussian.Covariance(_adjoint_cov(seen[j], cand_cov[j])),
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

    # --- initial values: known poses + odometry, decided poses + odometry ---
    initial, anchored_from = {}, {}
    for r, robot in enumerate(run.robots):
        times = node_times[r]
        poses: list = [None] * len(times)
        if robot.initial_pose is not None and len(times):
            poses[0] = robot.initial_pose
        for k, p in decided_pose.get(r, {}).items():
            if poses[k] is None:
                poses[k] = p
        seeds = [k for k, p in enumerate(poses) if p is not None]
        if not seeds:
            if len(times):
                skips.add(
                    "unanchored_robot",
                    f"robot {robot.name}: no initial pose and no decided candidate set; "
                    f"its {len(times)} poses are left out",
                    len(times),
                )
            continue
        anchored_from[r] = times[seeds[0]]
        for k in range(seeds[0] + 1, len(times)):
            if poses[k] is None:
                poses[k] = poses[k - 1].compose(_step(step_rel[r], k, config)[0])
        for k in range(seeds[0] - 1, -1, -1):
            poses[k] = poses[k + 1].compose(_step(step_rel[r], k + 1, config)[0].inverse())
        for k, p in enumerate(poses):
            initial[pose_key(r, k)] = p
    for lkey, guess in landmark_guess.items():
        if isinstance(guess, tuple) and guess and guess[0] == "from":
            _, r, k, direction, rng = guess
            if pose_key(r, k) in initial:
                initial[lkey] = initial[pose_key(r, k)].transformFrom(direction * rng)
        else:
            initial[lkey] = np.asarray(guess, dtype=float)

    # --- steps: factors grouped by the time of their newest pose; unanchored robots dropped ---
    factors.sort(key=lambda f: f[0])
    kept, types = [], []
    dropped = 0
    for t, f, kind in factors:
        if all(key in initial for key in f.keys()):
            kept.append((t, f, kind))
            types.append(kind)
        else:
            dropped += 1
    if dropped:
        skips.add(
            "unanchored_robot",
            f"{dropped} factors touch poses of robots that nothing places",
            dropped,
        )
    step_times = np.unique([k[0] for k in kept]) if kept else np.zeros(0)
    steps, j = [], 0
    for t in step_times:
        group = []
        while j < len(kept) and kept[j][0] == t:
            group.append(kept[j][1:])
            j += 1
        steps.append((float(t), group))
    counts = {
        "robots": R,
        "poses": len([k for k in initial if decode(k)[0] == "x"]),
        "candidate_sets": len(run.observations),
        "committed_sets": sum(d.committed >= 0 for d in decisions),
        "landmark_anchors": n_anchor,
        "steps": len(steps),
        "excluded_by_option": excluded,
        **{f"factors_{name}": types.count(name) for name in sorted(set(types))},
    }
    return TeamGraph(
        run,
        config,
        node_times,
        initial,
        steps,
        types,
        decisions,
        anchored_from,
        step_rel,
        counts,
        skips,
        run_precision(run),
    )


def run_precision(run: TeamRun) -> float:
    """The scale [m, rad] of the run's estimates, for iSAM2's thresholds: FINE_PRECISION when
    the run holds candidate sets (camera poses from pixels: the fused estimate is mm-precise even
    where one P3P candidate is cm-precise along its depth), else COARSE_PRECISION (wheel odometry
    and range-bearing, decimetre-level)."""
    return FINE_PRECISION if run.observations else COARSE_PRECISION


SAME_POSE_GATE = 12.59  # chi2(6) at 95 %: two candidates this close are one pose for the decision


def _same_pose(poses: list, cov: np.ndarray, j: int) -> list[int]:
    """Candidate j and the candidates that are the same pose within their covariances
    (Mahalanobis^2 of the difference below SAME_POSE_GATE): near the P3P fold two solutions
    nearly coincide and share the posterior, and either one is the answer."""
    out = []
    for i, p in enumerate(poses):
        e = gtsam.Pose3.Logmap(poses[j].between(p))
        if i == j or e @ np.linalg.solve(cov[i] + cov[j], e) < SAME_POSE_GATE:
            out.append(i)
    return out


def _landmark_key(lid: int, lm_prior: dict, config: GraphConfig, n_anchor: int):
    prior = lm_prior.get(lid)
    if prior is not None and config.anchor_known_landmarks:
        return landmark_key(ANCHOR_BASE + n_anchor), prior
    return landmark_key(lid), prior


def _dead_reckoning(robot, steps: list, config: GraphConfig) -> list:
    """(pose, 6x6 covariance) of each of a robot's poses: its initial pose (and prior) chained
    through its odometry steps, covariances propagated to first order (right perturbations)."""
    sig = config.static_sigma if robot.static else (robot.initial_sigma or config.initial_sigma)
    out = [(robot.initial_pose, _cov(sig))]
    for k in range(1, len(steps)):
        step, c = _step(steps, k, config)
        pose, cov = out[-1]
        out.append((pose.compose(step), _adjoint_cov(step.inverse(), cov) + c))
    return out


def _between(r: int, k0: int, k1: int, rel: gtsam.Pose3, cov: np.ndarray, config: GraphConfig):
    noise = robust_noise(
        gtsam.noiseModel.Gaussian.Covariance(cov), config.kernels.kernel("odometry")
    )
    return gtsam.BetweenFactorPose3(pose_key(r, k0), pose_key(r, k1), rel, noise)


def _step(steps: list, k: int, config: GraphConfig) -> tuple:
    return steps[k] if steps[k] is not None else (gtsam.Pose3(), _cov(config.unknown_motion_sigma))


def _compose_steps(steps: list, k0: int, k1: int, config: GraphConfig) -> tuple:
    """Relative pose from node k0 to k1 and its first-order covariance (right perturbations)."""
    rel, cov = gtsam.Pose3(), np.zeros((6, 6))
    for k in range(k0 + 1, k1 + 1):
        step, c = _step(steps, k, config)
        cov = _adjoint_cov(step.inverse(), cov) + c
        rel = rel.compose(step)
    return rel, cov


def _point_factor(m, key, lkey, direction, rng, kernel, E):
    if m.kind == "range_bearing":
        return landmark_factor_3d(
            key, lkey, direction, rng, (m.bearing_sigma, m.bearing_sigma, m.range_sigma), kernel
        )
    if np.linalg.norm(E.translation()) > 1e-9:
        raise ValueError(
            f"{m.kind} to landmark {m.landmark}: a sensor offset from the body origin is "
            "supported for range-bearing and robot targets only"
        )
    if m.kind == "bearing":
        d = E.rotation().rotate(direction)
        noise = robust_noise(gtsam.noiseModel.Isotropic.Sigma(2, m.bearing_sigma), kernel)
        return gtsam.BearingFactor3D(key, lkey, gtsam.Unit3(d), noise)
    noise = robust_noise(gtsam.noiseModel.Isotropic.Sigma(1, m.range_sigma), kernel)
    return gtsam.RangeFactor3D(key, lkey, float(rng), noise)


def _robot_factor(m, key, tkey, direction, rng, kernel, E):
    if m.kind == "range_bearing":
        return robot_factor_3d(
            key, tkey, direction, rng, (m.bearing_sigma, m.bearing_sigma, m.range_sigma), kernel
        )
    if m.kind == "bearing":
        return bearing_factor(key, tkey, direction, m.bearing_sigma, body_T_camera=E, kernel=kernel)
    identity = np.allclose(E.matrix(), np.eye(4))
    return range_factor(key, tkey, rng, m.range_sigma, None if identity else E, kernel)


def _corrected_range_bearings(run: TeamRun, node_times: list, config: GraphConfig) -> dict:
    """Range-bearing rows of wheel-odometry robots re-expressed in the body frame at the grid
    time they join (the observer's own motion over <= dt/2 integrated from its odometry):
    index -> (direction (3,), range) in the body frame."""
    out = {}
    for r in range(len(run.robots)):
        od = run.velocity[r]
        idx = [i for i, m in enumerate(run.points) if m.robot == r and m.kind == "range_bearing"]
        if not len(od) or not idx:
            continue
        times = node_times[r]
        t = np.array([run.points[i].time for i in idx])
        frame = np.clip(np.rint((t - times[0]) / config.keyframe_dt).astype(int), 0, len(times) - 1)
        stamps = np.union1d(times, t)
        poses = integrate_unicycle(
            od[:, 0], od[:, 1], od[:, 2], stamps, velocity_noise(run, r, config)
        ).poses
        at_meas = poses[np.searchsorted(stamps, t)]
        at_frame = poses[np.searchsorted(stamps, times[frame])]
        pts = np.array(
            [
                run.points[i].body_T_sensor.transformFrom(
                    run.points[i].direction * run.points[i].range
                )
                for i in idx
            ]
        )
        c, s = np.cos(at_meas[:, 2]), np.sin(at_meas[:, 2])
        world = at_meas[:, :2] + np.column_stack(
            [c * pts[:, 0] - s * pts[:, 1], s * pts[:, 0] + c * pts[:, 1]]
        )
        d = world - at_frame[:, :2]
        c, s = np.cos(at_frame[:, 2]), np.sin(at_frame[:, 2])
        local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], pts[:, 2]])
        rng = np.linalg.norm(local, axis=1)
        for j, i in enumerate(idx):
            out[i] = (local[j] / rng[j], float(rng[j]))
    return out


@dataclass(frozen=True)
class TeamResult:
    """estimate[r]: (K_r,7) x y z qx qy qz qw per pose (NaN where left out); causal[r]: the
    online estimate of each pose right after its own step (NaN in batch); latencies (steps,);
    step_log: one row per session step (step index in graph.steps, time, latency [s], CPU [s],
    factors added, variables the solver holds); dropped: factors not added because they touch
    a variable the fixed lag has marginalized, by type; partial: the solve stopped early
    (`stop`) after `steps_done` of the graph's steps."""

    mode: str
    node_times: list
    estimate: list
    causal: list
    dead_reckoning: list
    latencies: np.ndarray
    wall_s: float
    graph: TeamGraph
    downweighted: dict
    landmarks: (
        dict  # landmark id -> estimated position (3,) of landmarks that are one variable (SLAM)
    )
    step_log: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    dropped: dict = field(default_factory=dict)
    partial: bool = False
    steps_done: int = 0
    lag: float | None = None


STEP_LOG_COLUMNS = ("step", "time", "latency_s", "cpu_s", "factors", "variables")


def _pose_row(p: gtsam.Pose3) -> np.ndarray:
    q = p.rotation().toQuaternion()
    t = p.translation()
    return np.array([t[0], t[1], t[2], q.x(), q.y(), q.z(), q.w()])


def solve(
    graph: TeamGraph,
    mode: str = "batch",
    progress: bool = False,
    stop=None,
    on_step=None,
    on_stop=None,
) -> TeamResult:
    """Batch: every step added, one LM solve. Online: one iSAM2 update per step (with
    `config.lag` > 0 a fixed-lag smoother, `Session`); a new pose is predicted from its robot's
    latest estimate and odometry; robots enter at their first anchor; a factor touching a
    marginalized variable is left out and counted (`TeamResult.dropped`). stop(): checked
    before every online step and between LM iterations, True ends the solve there (the result
    is marked partial: online, the estimate after the last finished step; batch, the LM
    iterate).
    on_step(i): called after graph step i was consumed; on_stop(steps_done): when stop()
    ended the online loop."""
    from dataclasses import replace

    from graphloc.factors.robust import downweighted

    cfg = graph.config
    lag = float(cfg.lag or 0.0) if mode == "online" else 0.0
    session = Session(
        replace(cfg.session_config(mode, graph.precision), lag=lag),
        progress=progress and mode == "batch",
        stop=stop,
    )
    causal = [np.full((len(t), 7), np.nan) for t in graph.node_times]
    start = _time.perf_counter()
    added: set = set()
    held: list = []  # online: factors on robots not yet anchored
    latest: dict = {}
    types: list = []  # factor types in the order the session holds them
    dropped: dict = {}
    log: list = []
    partial, done = False, 0
    # online: until the last robot is anchored, factors on robots not yet anchored wait
    hold_until = max(graph.anchored_from.values(), default=-np.inf)
    if mode != "online":
        hold_until = -np.inf
    for i, (t, group) in enumerate(
        tqdm(graph.steps, desc=f"{mode} steps", disable=not progress, unit="step")
    ):
        if mode == "online" and stop is not None and stop():
            partial = True
            if on_stop is not None:
                on_stop(done)
            break
        done = i + 1
        values = gtsam.Values()
        factors = []
        waiting, held = held + group, []
        for f, kind in waiting:
            keys = f.keys()
            if t < hold_until and any(_held(graph, key, t) for key in keys):
                held.append((f, kind))
                continue
            if lag and any(session.marginalized(key) for key in keys):
                dropped[kind] = dropped.get(kind, 0) + 1
                continue
            for key in keys:
                if key not in added:
                    values.insert(key, _predict(graph, key, latest))
                    added.add(key)
            factors.append(f)
            types.append(kind)
        if factors:
            step = session.add(factors, values, time=t)
            log.append((i, t, step.latency_s, step.cpu_s, len(factors), session.live_variables()))
        if factors and mode == "online":
            new_poses = [k for k in values.keys() if decode(k)[0] == "x"]
            est = session.estimate(new_poses)
            for key in new_poses:
                _, r, k = decode(key)
                p = est.atPose3(key)
                causal[r][k] = _pose_row(p)
                if k >= latest.get(r, (-1, None))[0]:
                    latest[r] = (k, p)
        if on_step is not None:
            on_step(i)
    final = session.estimate()
    partial = partial or session.stopped
    wall = _time.perf_counter() - start
    estimate = []
    for r, times in enumerate(graph.node_times):
        rows = np.full((len(times), 7), np.nan)
        for k in range(len(times)):
            key = pose_key(r, k)
            if final.exists(key):
                rows[k] = _pose_row(final.atPose3(key))
        estimate.append(rows)
    dead = []
    for r, times in enumerate(graph.node_times):
        rows = np.full((len(times), 7), np.nan)
        for k in range(len(times)):
            key = pose_key(r, k)
            if key in graph.initial:
                rows[k] = _pose_row(graph.initial[key])
        dead.append(rows)
    down = {}
    types = np.array(types)
    for ftype in ("odometry", "landmark", "inter_robot", "candidate"):
        if cfg.kernels.kernel(ftype).name == "none" or not (types == ftype).any():
            continue
        rep = downweighted(
            session.graph, final, cfg.downweight_threshold, indices=np.flatnonzero(types == ftype)
        )
        down[ftype] = {
            "robust_factors": rep.n_robust,
            "downweighted": rep.n_downweighted,
            "threshold": cfg.downweight_threshold,
        }
    landmarks = {
        decode(k)[1]: np.asarray(final.atPoint3(k))
        for k in final.keys()
        if decode(k)[0] == "l" and decode(k)[1] < ANCHOR_BASE
    }
    step_log = np.array(log, dtype=float).reshape(-1, len(STEP_LOG_COLUMNS))
    return TeamResult(
        mode,
        graph.node_times,
        estimate,
        causal,
        dead,
        session.latencies(),
        wall,
        graph,
        down,
        landmarks,
        step_log,
        dropped,
        partial,
        done,
        lag if mode == "online" else None,
    )


def _held(graph: TeamGraph, key: int, t: float) -> bool:
    kind, r, _ = decode(key)
    return kind == "x" and graph.anchored_from.get(r, np.inf) > t


def _predict(graph: TeamGraph, key: int, latest: dict):
    """Initial value of a new variable: a landmark's guess; a pose from its robot's latest
    estimate composed with the odometry since, else the graph's initial guess."""
    kind, r, k = decode(key)
    if kind != "x":
        return graph.initial[key]
    if r in latest and latest[r][0] < k:
        k0, pose = latest[r]
        rel, _ = _compose_steps(graph.step_rel[r], k0, k, graph.config)
        if all(s is not None for s in graph.step_rel[r][k0 + 1 : k + 1]):
            return pose.compose(rel)
    return graph.initial[key]


def default_lag(run, config: GraphConfig) -> float:
    """The online lag when none is given: DEFAULT_LAG when every variable is only needed
    near its own time -- no static robot (its one pose is observed all run long) and no
    landmark estimated as one variable (SLAM) -- else 0 (full smoothing): the fixed-lag
    smoother stamps a variable once (`graphloc.session.SessionConfig`), so a long-lived one
    would leave the window and every later factor on it would be dropped."""
    static = any(r.static for r in run.robots)
    slam = config.use_landmarks and not (
        config.landmark_priors and run.landmarks_known and config.anchor_known_landmarks
    )
    return 0.0 if static or slam else DEFAULT_LAG
