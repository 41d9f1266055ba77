"""Ground + ceiling laser map fusion (seed 004, Kaushik et al.), as one factor graph: per-robot
KISS-ICP odometry; the inter-robot guess (the LED tracker of `led_guess`, seed 004 Sec. II-B /
II-C, or a user's hint); `robust_register` of the first ceiling scan onto the first ground scan
from it (Sec. IV), or `FusionRejected`; one graph (prior, scan-matching between-factors, the
inter-robot factor, the P3P max-mixtures) solved by LM; the fused map. Everything is expressed
in G_0, the ground LiDAR's first frame (the steps: docs/design_algorithms.md, "Map fusion").
"""

from __future__ import annotations

import time
from dataclasses import replace

import gtsam
import numpy as np

from graphloc.factors.odometry import between_factor
from graphloc.keys import pose_key
from graphloc.pipelines.map_fusion.options import FusionConfig
from graphloc.pipelines.map_fusion.types import (
    CEILING,
    GROUND,
    ROBOT_NAMES,
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
