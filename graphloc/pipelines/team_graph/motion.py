"""Each robot's pose times and motion: wheel-odometry grids integrated along arcs, relative-pose
tables, dead reckoning; the between factors, initial-pose priors and surface factors."""

from __future__ import annotations


import gtsam
import numpy as np

from graphloc.factors.odometry import VelocityNoise, integrate_unicycle
from graphloc.factors.robust import robust_noise
from graphloc.factors.surface import plane_attitude_factor, plane_distance_factor
from graphloc.keys import pose_key
from graphloc.pipelines.team_graph.config import GraphConfig, adjoint_cov, cov6
from graphloc.run import TeamRun, pose_from_planar


class Timeline:
    """Each robot's pose times and the pose a measurement at time t joins."""

    def __init__(self, run: TeamRun, config: GraphConfig):
        self.run, self.config = run, config
        self.node_times = node_times(run, config)

    def nearest(self, r: int, t: float) -> int:
        """Index of robot r's pose nearest t, -1 if none within dt/2 (wheel-odometry grid) or
        sync_tolerance (event-clocked robots)."""
        run, config = self.run, self.config
        times = self.node_times[r]
        if run.robots[r].static:
            return 0
        if not len(times):
            return -1
        n = len(times)
        i = min(max(int(times.searchsorted(t)), 1), n - 1) if n > 1 else 0
        if i > 0 and abs(times[i - 1] - t) <= abs(times[i] - t):
            i -= 1
        tol = config.keyframe_dt / 2 + 1e-9 if len(run.velocity[r]) else config.sync_tolerance
        return i if abs(times[i] - t) <= tol else -1

    def offsets(self, r: int, nodes, times) -> list:
        """Robot r's body at each of `times` in its body frame at node `nodes[i]`
        (gtsam.Pose3 each): a wheel-odometry robot's motion between its grid pose and the
        measurement's time integrated from its velocities (one vectorized pass); the identity
        for other robots (their poses are at their own time stamps, within `sync_tolerance`)."""
        od = self.run.velocity[r]
        if not len(od) or self.run.robots[r].static or not len(times):
            return [gtsam.Pose3()] * len(times)
        at_node = self.node_times[r][np.asarray(nodes, dtype=int)]
        stamps = np.union1d(at_node, np.asarray(times, dtype=float))
        noise = velocity_noise(self.run, r, self.config)
        poses = integrate_unicycle(od[:, 0], od[:, 1], od[:, 2], stamps, noise).poses
        a = poses[np.searchsorted(stamps, at_node)]
        b = poses[np.searchsorted(stamps, times)]
        return [pose_from_planar(*p0).between(pose_from_planar(*p1)) for p0, p1 in zip(a, b)]


def node_times(run: TeamRun, config: GraphConfig) -> list:
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
            measured = [p.time for p in run.points if r in (p.robot, p.target)]
            measured += [o.time for o in run.observations if r in (o.robot, o.target)]
            measured += [f.time for f in run.features if f.robot == r]
            if stamps:
                stamps += inserted_times(run, r, measured, config.sync_tolerance)
            else:
                stamps = measured
            times = np.unique(np.round(np.array(stamps, dtype=float), 9))
        out.append(times)
    return out


def consecutive_steps(run: TeamRun, r: int) -> list:
    """Robot r's relative-pose steps between consecutive stamps of its motions (no stamp of
    another of its steps strictly inside): its odometry, not a loop closure across several."""
    motions = [m for m in run.motions if m.robot == r]
    stamps = np.unique([t for m in motions for t in (m.t0, m.t1)])
    out = []
    for m in motions:
        a, b = sorted((m.t0, m.t1))
        i, j = np.searchsorted(stamps, a, "right"), np.searchsorted(stamps, b, "left")
        if i >= j:
            out.append(m)
    return out


def inserted_times(run: TeamRun, r: int, measured: list, tolerance: float) -> list:
    """Times of an event-clocked robot's measurements that are no stamp of its relative poses
    (farther than `tolerance` from every stamp) but lie inside one of its consecutive steps:
    poses there, the step split at them (`motion_factors`), so that a measurement between two
    odometry stamps is not dropped."""
    steps = consecutive_steps(run, r)
    if not steps or not measured:
        return []
    stamps = np.unique([t for m in steps for t in (m.t0, m.t1)])
    spans = np.array(sorted((min(m.t0, m.t1), max(m.t0, m.t1)) for m in steps))
    t = np.unique(np.asarray(measured, dtype=float))
    i = np.clip(np.searchsorted(stamps, t), 1, len(stamps) - 1)
    gap = np.minimum(np.abs(stamps[i - 1] - t), np.abs(stamps[i] - t))
    k = np.searchsorted(spans[:, 0], t, "right") - 1
    inside = (k >= 0) & (t < spans[np.clip(k, 0, None), 1])
    return t[(gap > tolerance) & inside].tolist()


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


def dead_reckoning(robot, steps: list, config: GraphConfig, known: list | None = None) -> list:
    """(pose, 6x6 covariance) of each of a robot's poses: its initial pose (and prior) chained
    through its odometry steps, covariances propagated to first order (right perturbations).
    known: the first poses of this list already made (a track grown as steps arrive)."""
    sig = config.static_sigma if robot.static else (robot.initial_sigma or config.initial_sigma)
    out = list(known) if known else [(robot.initial_pose, cov6(sig))]
    for k in range(len(out), len(steps)):
        step, c = step_or_unknown(steps, k, config)
        pose, cov = out[-1]
        out.append((pose.compose(step), adjoint_cov(step.inverse(), cov) + c))
    return out


def between_factor(
    r: int, k0: int, k1: int, rel: gtsam.Pose3, cov: np.ndarray, config: GraphConfig
):
    noise = robust_noise(
        gtsam.noiseModel.Gaussian.Covariance(cov), config.kernels.kernel("odometry")
    )
    return gtsam.BetweenFactorPose3(pose_key(r, k0), pose_key(r, k1), rel, noise)


def step_or_unknown(steps: list, k: int, config: GraphConfig) -> tuple:
    return steps[k] if steps[k] is not None else (gtsam.Pose3(), cov6(config.unknown_motion_sigma))


def compose_steps(
    steps: list, k0: int, k1: int, config: GraphConfig, covariance: bool = True
) -> tuple:
    """Relative pose from node k0 to k1 and its first-order covariance (right perturbations;
    None with `covariance` False: the pose alone, as an online prediction needs it)."""
    rel, cov = gtsam.Pose3(), np.zeros((6, 6)) if covariance else None
    for k in range(k0 + 1, k1 + 1):
        step, c = step_or_unknown(steps, k, config)
        if covariance:
            cov = adjoint_cov(step.inverse(), cov) + c
        rel = rel.compose(step)
    return rel, cov


def split_step(relative: gtsam.Pose3, covariance: np.ndarray, times: np.ndarray) -> list:
    """A relative-pose step over `times` (its start, the poses inserted inside it, its end)
    cut at each time at a constant twist: the piece over a fraction s of the step is
    Exp(s Log(relative)) with covariance s * covariance (they compose to the step exactly, and
    their covariances add up to its own)."""
    xi = gtsam.Pose3.Logmap(relative)
    fractions = np.diff(times) / (times[-1] - times[0])
    return [(gtsam.Pose3.Expmap(s * xi), s * covariance) for s in fractions]


def robot_anchors(r: int, robot, config: GraphConfig, times, k0: int = 0) -> list:
    """Robot r's anchors of its poses from k0 on: the prior on its known initial pose (k0 = 0)
    and its surface factors, (time, factor, type) each."""
    factors: list = []
    if robot.initial_pose is not None and len(times) and k0 == 0:
        sig = config.static_sigma if robot.static else (robot.initial_sigma or config.initial_sigma)
        factors.append(
            (
                times[0],
                gtsam.PriorFactorPose3(
                    pose_key(r, 0),
                    robot.initial_pose,
                    gtsam.noiseModel.Gaussian.Covariance(cov6(sig)),
                ),
                "prior",
            )
        )
    if robot.surface is not None:
        sigma = config.surface_sigma if robot.surface_sigma is None else robot.surface_sigma
        for k in range(k0, len(times)):
            t = times[k]
            if sigma > 0:  # 0: attitude only
                factors.append(
                    (t, plane_distance_factor(pose_key(r, k), robot.surface, sigma), "surface")
                )
            if robot.attitude_sigma is not None:
                f = plane_attitude_factor(
                    pose_key(r, k), robot.surface, robot.attitude_sigma, robot.body_axis
                )
                factors.append((t, f, "surface"))
    return factors


def place_robot(run, r, node_times, step_rel, config, decided_pose, placed_via, poses):
    """Robot r's initial poses ([Pose3 per node], first seeded node) from its known initial
    pose, its decided poses or a placed robot's pose (`placed_via`), carried along its own
    steps; None if nothing places it."""
    times = node_times[r]
    out: list = [None] * len(times)
    if run.robots[r].initial_pose is not None and len(times):
        out[0] = run.robots[r].initial_pose
    for k, p in decided_pose.get(r, {}).items():
        if out[k] is None:
            out[k] = p
    for k, (o, ko, rel) in placed_via.get(r, {}).items():
        if out[k] is None and o in poses:
            out[k] = poses[o][0][ko].compose(rel)
    seeds = [k for k, p in enumerate(out) if p is not None]
    if not seeds:
        return None
    for k in range(seeds[0] + 1, len(times)):
        if out[k] is None:
            out[k] = out[k - 1].compose(step_or_unknown(step_rel[r], k, config)[0])
    for k in range(seeds[0] - 1, -1, -1):
        out[k] = out[k + 1].compose(step_or_unknown(step_rel[r], k + 1, config)[0].inverse())
    return out, seeds[0]
