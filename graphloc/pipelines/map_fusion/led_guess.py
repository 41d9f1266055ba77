"""The inter-robot initial guess of map fusion from the ceiling camera's view of the ground
robot's LEDs (seed 004 Sec. II-B / II-C): P3P candidate sets of every camera frame
(`p3p_candidate_sets`), expressed in G_0 with the ground robot's odometry, disambiguated over
the climbing robot's motion by the `HypothesisTracker` (the role of seed 004's particle filter,
Algorithm 2); the guess's covariance (`guess_covariance`); every frame's set a max-mixture
factor of the fusion graph (`p3p_factors`)."""

from __future__ import annotations

import time
from dataclasses import replace

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.mixture import (
    MaxMixture,
    component_factors,
    max_mixture_factor,
    mixture_weights,
)
from graphloc.hypotheses import HypothesisTracker, cap_covariances
from graphloc.keys import pose_key
from graphloc.mapping.odometry import OdometryResult
from graphloc.pipelines.map_fusion.options import FusionConfig
from graphloc.pipelines.map_fusion.types import (
    CEILING,
    GROUND,
    GuessResult,
    LedObservations,
)
from graphloc.seams import Odometry
from graphloc.vision.marker_poses import p3p_candidate_sets


def led_candidates(leds: LedObservations, times: np.ndarray, cfg: FusionConfig):
    """P3P candidate sets (camera poses in G_k, `p3p_candidate_sets` with cfg.pixel_sigma:
    typed first-order covariances) of every camera frame that sees all three LEDs. Returns
    ({frame: CandidateSet}, count of frames without a set)."""
    F = len(leds.pixels)
    frames = np.flatnonzero(np.isfinite(leds.pixels).all(axis=(1, 2)))
    sets = p3p_candidate_sets(
        leds.camera,
        list(leds.pixels[frames]),
        [np.arange(3)] * len(frames),
        np.asarray(leds.leds, dtype=float),
        np.asarray(times, dtype=float)[frames],
        cfg.pixel_sigma,
        observer="ceiling",
        observed="ground",
    )
    out = {int(f): cs for f, cs in zip(frames, sets) if cs is not None and len(cs)}
    return out, F - len(out)


def _in_first_frame(cands: CandidateSet, T_g0_gk: np.ndarray) -> CandidateSet:
    """Candidates (camera in G_k) re-expressed in G_0 (right-perturbation covariances unchanged)."""
    R = np.einsum("ij,kjl->kil", T_g0_gk[:3, :3], cands.R)
    t = cands.t @ T_g0_gk[:3, :3].T + T_g0_gk[:3, 3]
    return replace(cands, R=R, t=t)


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
    cov = cands.covariance
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


def p3p_factors(guess: GuessResult, T_cc: np.ndarray, outlier_d2: float) -> list[MaxMixture]:
    """One max-mixture x(ground,k) -> x(ceiling,k) per camera frame with candidates
    (`factors.mixture`: `component_factors`, `mixture_weights`, `max_mixture_factor`):
    component j is candidate j (the camera in G_k) carried to the ceiling LiDAR, Y_j T_cc^-1,
    with its covariance carried through the extrinsic (T Exp(xi) M = T M Exp(Ad(M^-1) xi),
    M = T_cc^-1); weights from the scores. The solve picks, per frame, the component nearest
    the estimate (Olson & Agarwal, RSS 2012). A last, null component (their null hypothesis:
    the frame is an outlier) is the best-weighted candidate with its covariance scaled by
    s^2 = exp(outlier_d2 / 6) and that candidate's weight: its normalizer is 6 ln s =
    outlier_d2 / 2 above the candidate's, so it wins once every candidate is farther than
    Mahalanobis^2 ~ outlier_d2 from the estimate, and then pulls 1 / s^2 as hard."""
    ad = gtsam.Pose3(T_cc).AdjointMap()  # Ad(M^-1) with M = T_camera_ceiling
    T_cam_c = np.linalg.inv(T_cc)
    scale = float(np.exp(outlier_d2 / 6.0))
    out = []
    for f, cands in guess.candidates.items():
        rel = np.einsum("kij,jl->kil", np.stack([p.matrix() for p in cands.poses()]), T_cam_c)
        cov = np.einsum("ij,kjl,ml->kim", ad, cands.covariance, ad)
        cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
        carried = replace(cands, R=rel[:, :3, :3], t=rel[:, :3, 3], covariance=cov)
        keys = (pose_key(CEILING, f), pose_key(GROUND, f))
        weights = mixture_weights(carried)
        j = int(np.argmax(weights))
        null = component_factors(carried, *keys, covariances=scale * cov)[j]
        components = component_factors(carried, *keys) + [null]
        out.append(max_mixture_factor(components, np.r_[weights, weights[j]]))
    return out
