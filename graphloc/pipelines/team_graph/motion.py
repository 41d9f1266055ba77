"""A robot's motion: odometry noise, dead reckoning along its steps, the between factors,
initial-pose priors and surface factors."""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.factors.odometry import VelocityNoise
from graphloc.factors.robust import robust_noise
from graphloc.factors.surface import plane_attitude_factor, plane_distance_factor
from graphloc.keys import pose_key
from graphloc.pipelines.team_graph.config import GraphConfig, adjoint_cov, cov6
from graphloc.run import TeamRun


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
