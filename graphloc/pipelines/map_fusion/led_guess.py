"""The inter-robot initial guess of map fusion from the ceiling camera's view of the ground
robot's LEDs (seed 004 Sec. II-B / II-C): P3P on the three LED pixels of every camera frame (all
up to four solutions, `graphloc.geometry.p3p`, with first-order covariances), expressed in the
ground robot's first frame with its odometry, disambiguated over the climbing robot's motion by
the `HypothesisTracker` (the role of seed 004's particle filter, Algorithm 2); the guess's
covariance (`guess_covariance`); and the P3P between-factors of the fusion graph (`p3p_factors`).
Frames: G_k / C_k are the ground / ceiling LiDAR at frame k; everything is expressed in G_0."""

from __future__ import annotations

import time

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.odometry import between_factor
from graphloc.geometry.p3p import solve_p3p
from graphloc.geometry.resection import resection_covariance
from graphloc.hypotheses import HypothesisTracker, cap_covariances
from graphloc.keys import pose_key
from graphloc.pipelines.map_fusion.types import (
    CEILING,
    GROUND,
    FusionConfig,
    GuessResult,
    LedObservations,
)
from graphloc.mapping.odometry import OdometryResult
from graphloc.seams import Odometry


def led_candidates(leds: LedObservations, times: np.ndarray, cfg: FusionConfig):
    """P3P candidate sets of every camera frame with all three LEDs (camera poses in G_k) and
    their first-order covariances. Returns ({frame: CandidateSet}, skipped frame count)."""
    F = len(leds.pixels)
    bearings, ok = leds.camera.pixel_to_bearing(leds.pixels.reshape(-1, 2))
    bearings, ok = bearings.reshape(F, 3, 3), ok.reshape(F, 3).all(axis=1)
    frames = np.flatnonzero(ok)
    out = {}
    if len(frames) == 0:
        return out, F
    points = np.broadcast_to(np.asarray(leds.leds, dtype=float), (len(frames), 3, 3))
    sol = solve_p3p(bearings[frames], points, method=cfg.p3p_method)
    for i, f in enumerate(frames):
        keep = sol.valid[i]
        if not keep.any():
            continue
        cand = sol.candidate_set(i, time=float(times[f]), observer="ceiling", observed="ground")
        cov = resection_covariance(
            leds.camera,
            sol.R_wc[i][keep],
            sol.t_wc[i][keep],
            np.broadcast_to(points[i], (int(keep.sum()), 3, 3)),
            cfg.pixel_sigma,
        )
        out[int(f)] = CandidateSet(
            cand.R,
            cand.t,
            cand.scores,
            cand.time,
            cand.observer,
            cand.observed,
            cand.source,
            {"covariance": cov},
        )
    return out, F - len(out)


def _in_first_frame(cands: CandidateSet, T_g0_gk: np.ndarray) -> CandidateSet:
    """Candidates (camera in G_k) re-expressed in G_0 (right-perturbation covariances unchanged)."""
    R = np.einsum("ij,kjl->kil", T_g0_gk[:3, :3], cands.R)
    t = cands.t @ T_g0_gk[:3, :3].T + T_g0_gk[:3, 3]
    return CandidateSet(
        R, t, cands.scores, cands.time, cands.observer, cands.observed, cands.source, cands.meta
    )


def guess_covariance(
    cands: CandidateSet,
    T_g0_camK: np.ndarray,
    T_g0_gk: np.ndarray,
    cam_in_c0: np.ndarray,
    frames: int,
    cfg: FusionConfig,
) -> np.ndarray:
    """Right-perturbation covariance of T_G0_C0 = T_G0_Gk Y X^-1 (Y: the camera in G_k, one P3P
    candidate; X: the camera in C_0 by the ceiling odometry): the candidate nearest to the tracker's
    estimate T_G0_camK (Mahalanobis) brings its first-order covariance C_Y, the ground and ceiling
    odometry over `frames` steps bring Q each; C_Y capped at cfg.tracker.max_candidate_std (the
    tracker's linearization trust region) (cfg.odometry_sigmas^2 per step). With
    T Exp(d) M = T M Exp(Ad(M^-1) d): Sigma = Ad_X (Ad_Y^-1 Q Ad_Y^-T + C_Y + Q) Ad_X^T."""
    cov = cands.meta["covariance"]
    predicted = gtsam.Pose3(np.linalg.inv(T_g0_gk) @ T_g0_camK)
    d2 = [
        float(e @ np.linalg.solve(c, e))
        for e, c in ((predicted.localCoordinates(pose), c) for pose, c in zip(cands.poses(), cov))
    ]
    j = int(np.argmin(d2))
    Y = cands.poses()[j]
    s_rot, s_tr = cfg.odometry_sigmas
    Q = np.diag(np.r_[np.full(3, s_rot**2), np.full(3, s_tr**2)]) * max(frames, 1)
    ad_y_inv = Y.inverse().AdjointMap()
    ad_x = gtsam.Pose3(cam_in_c0).AdjointMap()
    C_y = cap_covariances(cov[j][None], cfg.tracker.max_candidate_std)[0]  # as the tracker does
    out = ad_x @ (ad_y_inv @ Q @ ad_y_inv.T + C_y + Q) @ ad_x.T
    return 0.5 * (out + out.T)


def led_initial_guess(
    leds: LedObservations,
    times: np.ndarray,
    odo_g: OdometryResult,
    odo_c: OdometryResult,
    cfg: FusionConfig,
) -> GuessResult:
    """Seed 004 Sec. II-C with the HypothesisTracker: every frame's P3P candidates (camera in G_0
    via the ground odometry) and the ceiling camera's odometry between observed frames; the
    committed (else most probable) track at the last frame, carried back to C_0 by the ceiling
    odometry."""
    start = time.perf_counter()
    cands, skipped = led_candidates(leds, times, cfg)
    if not cands:
        raise ValueError("LED observations: no camera frame with all three LEDs and a P3P solution")
    T_cc = np.asarray(leds.T_ceiling_camera, dtype=float)
    cam_in_c0 = odo_c.poses @ T_cc  # camera poses in C_0
    tracker = HypothesisTracker(cfg.tracker)
    s_rot, s_tr = cfg.odometry_sigmas
    prev, decision = None, None
    for f in sorted(cands):
        c0 = _in_first_frame(cands[f], odo_g.poses[f])
        if prev is None:
            decision = tracker.update(c0)
        else:
            rel = np.linalg.inv(cam_in_c0[prev]) @ cam_in_c0[f]
            n = f - prev
            cov = np.diag(np.r_[np.full(3, s_rot**2), np.full(3, s_tr**2)]) * n
            decision = tracker.update(c0, Odometry(gtsam.Pose3(rel), cov))
        prev = f
    if decision is None or decision.pose is None:
        raise ValueError("LED observations: the hypothesis tracker kept no hypothesis")
    T_g0_camK = decision.pose.matrix()
    T_g0_c0 = T_g0_camK @ np.linalg.inv(cam_in_c0[prev])
    p = (
        float(decision.probabilities[decision.committed])
        if decision.committed >= 0
        else float(decision.probabilities.max(initial=0.0))
    )
    frames = np.array(sorted(cands))
    cov = guess_covariance(cands[prev], T_g0_camK, odo_g.poses[prev], cam_in_c0[prev], prev, cfg)
    return GuessResult(
        T_g0_c0,
        frames,
        np.array([len(cands[f]) for f in frames]),
        bool(decision.locked),
        p,
        cands,
        time.perf_counter() - start,
        skipped,
        cov,
    )


def p3p_factors(
    guess: GuessResult, T_cc: np.ndarray, poses_g: np.ndarray, poses_c: np.ndarray, gate: float
):
    """One BetweenFactorPose3 x(ground,k) -> x(ceiling,k) per camera frame: the P3P candidate
    closest (Mahalanobis) to the current estimate, if within `gate`; covariance carried through the
    camera->LiDAR extrinsic (T Exp(xi) M = T M Exp(Ad(M^-1) xi))."""
    factors = []
    ad = gtsam.Pose3(T_cc).AdjointMap()  # Ad(M^-1) with M = T_camera_ceiling
    T_cam_c = np.linalg.inv(T_cc)
    for f, cands in guess.candidates.items():
        predicted = gtsam.Pose3(np.linalg.inv(poses_g[f]) @ poses_c[f] @ T_cc)  # camera in G_k
        cov = cands.meta["covariance"]
        d2 = []
        for pose, c in zip(cands.poses(), cov):
            e = predicted.localCoordinates(pose)
            d2.append(float(e @ np.linalg.solve(c, e)))
        j = int(np.argmin(d2))
        if d2[j] > gate:
            continue
        rel = cands.poses()[j].matrix() @ T_cam_c
        factors.append(
            between_factor(pose_key(GROUND, f), pose_key(CEILING, f), rel, ad @ cov[j] @ ad.T)
        )
    return factors
