"""Ground + ceiling laser map fusion (seed 004, Kaushik et al.), as one factor graph.

1. per robot KISS-ICP odometry over its scans (`graphloc.mapping.odometry`);
2. inter-robot initial guess: P3P on the three LED pixels of every camera frame (seed 004
   Sec. II-B, all up to four solutions, `graphloc.geometry.p3p`), expressed in the ground
   robot's first frame with its odometry, disambiguated over the climbing robot's motion by the
   `HypothesisTracker` (the role of seed 004 Sec. II-C's particle filter, Algorithm 2;
   `graphloc.pipelines.map_fusion.led_guess`); or a user-supplied relative pose hint;
3. denoise + point-to-plane ICP of the first ceiling scan onto the first ground scan from that
   guess (seed 004 Sec. IV): `robust_register` starts from the guess and the sigma points of its
   covariance (the P3P candidate's, `guess_covariance`, or the hint's sigmas), keeps
   the candidate of lowest truncated cost (a point beside a surface of the other scan costs
   more than one the other robot did not see) and accepts it only if its checks pass (overlap,
   residual consistency, conditioning, agreement with the guess, the ceiling robot above the
   ground robot, its own covariance); otherwise `fuse` raises `FusionRejected` ("not fused",
   with why);
4. one graph: prior on the ground robot's first pose, scan-matching between-factors for both
   robots (point-to-plane ICP of consecutive scans from the KISS-ICP increment, covariance from
   the registration's information matrix), the ICP inter-robot factor, and per camera frame a
   max-mixture of the P3P candidates' between-factors and a null component (the solve
   chooses; a frame farther than `p3p_outlier_d2` from the estimate is an outlier); batch
   Levenberg-Marquardt (`graphloc.session.Session`);
5. fused map: every scan placed with the optimized poses, denoised, each point labelled with
   its robot.

Frames: G_k / C_k are the ground / ceiling LiDAR at frame k; everything is expressed in G_0.
The configuration, inputs and results are `graphloc.pipelines.map_fusion.types`.
"""

from __future__ import annotations

import time
from dataclasses import replace

import gtsam
import numpy as np

from graphloc.factors.odometry import between_factor
from graphloc.keys import pose_key
from graphloc.pipelines.map_fusion.types import (
    CEILING,
    GROUND,
    ROBOT_NAMES,
    FusionConfig,
    FusionInput,
    FusionRejected,
    FusionResult,
)
from graphloc.pipelines.map_fusion.led_guess import led_initial_guess, p3p_factors
from graphloc.mapping.odometry import OdometryResult, run_odometry
from graphloc.mapping.registration import denoise, prepare, refine
from graphloc.mapping.registration_starts import hint_covariance
from graphloc.mapping.robust_registration import robust_register
from graphloc.session import Session


def _between_steps(
    odo: OdometryResult, prepared: list, cfg: FusionConfig
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """(relative T_{k-1,k}, 6x6 covariance, seconds) per step of one robot: point-to-plane ICP of
    scan k onto scan k-1 from the KISS-ICP increment with its information matrix
    (cfg.scan_matching), else the KISS-ICP increment with cfg.odometry_sigmas."""
    s_rot, s_tr = cfg.odometry_sigmas
    fixed = np.diag(np.r_[np.full(3, s_rot**2), np.full(3, s_tr**2)])
    steps = []
    for k, inc in enumerate(odo.increments(), start=1):
        if not cfg.scan_matching:
            steps.append((inc, fixed, 0.0))
            continue
        r = refine(prepared[k], prepared[k - 1], inc, cfg.registration)
        steps.append((r.transformation, np.linalg.inv(r.information), r.seconds))
    return steps


def fuse(inp: FusionInput, cfg: FusionConfig = FusionConfig()) -> FusionResult:
    """The whole pipeline of the module docstring."""
    timings = {}
    t0 = time.perf_counter()
    odo = {
        GROUND: run_odometry(inp.ground_scans, cfg.odometry),
        CEILING: run_odometry(inp.ceiling_scans, cfg.odometry),
    }
    timings["odometry_s"] = time.perf_counter() - t0

    guess_info = None
    if inp.leds is not None:
        guess_info = led_initial_guess(inp.leds, inp.times, odo[GROUND], odo[CEILING], cfg)
        guess = guess_info.T_g0_c0
        timings["p3p_tracker_s"] = guess_info.seconds
    else:
        guess = np.asarray(inp.hint, dtype=float)

    t0 = time.perf_counter()
    n_prep = len(inp.times) if cfg.scan_matching else 1
    prepared = {
        r: [  # the first scans meet the other robot's; the rest only their predecessors
            prepare(s, cfg.registration, inter_robot=i == 0) for i, s in enumerate(scans[:n_prep])
        ]
        for r, scans in ((GROUND, inp.ground_scans), (CEILING, inp.ceiling_scans))
    }
    timings["denoise_s"] = time.perf_counter() - t0
    decision = None
    if cfg.robust:
        if guess_info is not None:
            hint_cov = guess_info.covariance
        else:
            hint_cov = hint_covariance(*(inp.hint_sigma or cfg.guess_sigma))
        decision = robust_register(
            prepared[CEILING][0],
            prepared[GROUND][0],
            guess,
            hint_cov,
            cfg.registration,
            cfg.acceptance,
        )
        if not decision.accepted:
            raise FusionRejected(decision, guess, guess_info)
        reg = decision.registration
    else:
        reg = refine(prepared[CEILING][0], prepared[GROUND][0], guess, cfg.registration)
    timings["icp_s"] = reg.seconds
    steps = {r: _between_steps(odo[r], prepared[r], cfg) for r in (GROUND, CEILING)}
    timings["scan_matching_s"] = sum(st[2] for r in steps for st in steps[r])

    # ---- one graph, one optimizer
    t0 = time.perf_counter()
    F = len(inp.times)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    graph.add(
        gtsam.PriorFactorPose3(
            pose_key(GROUND, 0),
            gtsam.Pose3(),
            gtsam.noiseModel.Isotropic.Sigma(6, cfg.anchor_sigma),
        )
    )
    init_poses = {}
    for r in (GROUND, CEILING):
        chain = [np.eye(4)]
        for k, (inc, cov, _) in enumerate(steps[r], start=1):
            graph.add(between_factor(pose_key(r, k - 1), pose_key(r, k), inc, cov))
            chain.append(chain[-1] @ inc)
        init_poses[r] = (np.eye(4) if r == GROUND else reg.transformation) @ np.asarray(chain)
        for k in range(F):
            values.insert(pose_key(r, k), gtsam.Pose3(init_poses[r][k]))
    graph.add(
        between_factor(
            pose_key(GROUND, 0),
            pose_key(CEILING, 0),
            reg.transformation,
            np.linalg.inv(reg.information),
        )
    )
    mixtures = []
    if guess_info is not None:
        T_cc = np.asarray(inp.leds.T_ceiling_camera, dtype=float)
        mixtures = p3p_factors(guess_info, T_cc, cfg.p3p_outlier_d2)
        for mixture in mixtures:
            graph.add(mixture.factor)
    session = Session(cfg.session)
    session.add(graph, values, time=float(inp.times[0]))
    est = session.estimate()
    poses = {
        r: np.array([est.atPose3(pose_key(r, k)).matrix() for k in range(F)])
        for r in (GROUND, CEILING)
    }
    errors = (float(graph.error(values)), float(graph.error(est)))
    timings["graph_s"] = time.perf_counter() - t0

    # ---- fused map
    t0 = time.perf_counter()
    pts, labels, outliers = [np.zeros((0, 3))], [np.zeros(0, dtype=int)], {}
    for r, scans in (
        ((GROUND, inp.ground_scans), (CEILING, inp.ceiling_scans)) if cfg.build_map else ()
    ):
        cloud = np.concatenate([s @ P[:3, :3].T + P[:3, 3] for s, P in zip(scans, poses[r])])
        pcd, outliers[ROBOT_NAMES[r]], _ = denoise(
            cloud, replace(cfg.registration, voxel=cfg.map_voxel)
        )
        p = pcd.point.positions.numpy().astype(float)
        pts.append(p)
        labels.append(np.full(len(p), r))
    timings["map_s"] = time.perf_counter() - t0
    T = np.linalg.inv(poses[GROUND][0]) @ poses[CEILING][0]
    return FusionResult(
        poses,
        odo,
        T,
        guess,
        guess_info,
        reg,
        len(mixtures),
        np.concatenate(pts),
        np.concatenate(labels),
        timings,
        errors,
        outliers,
        decision,
    )
