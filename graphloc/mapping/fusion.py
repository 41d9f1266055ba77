"""Ground + ceiling laser map fusion (seed 004, Kaushik et al.), as one factor graph.

1. per robot KISS-ICP odometry over its scans (`graphloc.mapping.odometry`);
2. inter-robot initial guess: P3P on the three LED pixels of every camera frame (seed 004
   Sec. II-B, all up to four solutions, `graphloc.geometry.p3p`), expressed in the ground
   robot's first frame with its odometry, disambiguated over the climbing robot's motion by the
   `HypothesisTracker` (the role of seed 004 Sec. II-C's particle filter, Algorithm 2);
   or a user-supplied relative pose hint;
3. denoise + point-to-plane ICP of the first ceiling scan onto the first ground scan from that
   guess (seed 004 Sec. IV): `robust_register` starts from the guess and the sigma points of its
   covariance (the P3P candidate's, `guess_covariance`, or the hint's sigmas), keeps
   the candidate with the lowest truncated point-to-plane cost and accepts it only if its checks
   pass (overlap, residual consistency, conditioning, agreement with the guess, the ceiling robot
   above the ground robot); otherwise `fuse` raises `FusionRejected` ("not fused", with why);
4. one graph: prior on the ground robot's first pose, scan-matching between-factors for both
   robots (point-to-plane ICP of consecutive scans from the KISS-ICP increment, covariance from
   the registration's information matrix), the ICP inter-robot factor, and a P3P between-factor
   per camera frame (the candidate that agrees with the registered estimate); batch
   Levenberg-Marquardt (`graphloc.session.Session`);
5. fused map: every scan placed with the optimized poses, denoised, each point labelled with
   its robot.

Frames: G_k / C_k are the ground / ceiling LiDAR at frame k; everything is expressed in G_0.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import gtsam
import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.candidates import CandidateSet
from graphloc.factors.odometry import between_factor
from graphloc.geometry.p3p import solve_p3p
from graphloc.hypotheses import HypothesisTracker, TrackerConfig, cap_covariances
from graphloc.keys import pose_key
from graphloc.mapping.odometry import OdometryConfig, OdometryResult, run_odometry
from graphloc.mapping.registration import (
    AcceptanceConfig,
    Registration,
    RegistrationConfig,
    RegistrationDecision,
    denoise,
    prepare,
    refine,
    hint_covariance,
    robust_register,
)
from graphloc.seams import Odometry
from graphloc.session import Session, SessionConfig

GROUND, CEILING = 0, 1
ROBOT_NAMES = {GROUND: "ground", CEILING: "ceiling"}


@dataclass(frozen=True)
class FusionConfig:
    """odometry_sigmas: per-frame KISS-ICP increment sigmas (rot [rad], trans [m]); pixel_sigma:
    LED pixel noise [px] for the P3P covariances; p3p_gate: Mahalanobis^2 gate for the P3P factors;
    guess_sigma: 1-sigma (rot [rad], trans [m]) of a hint given without its own (the LED
    tracker's guess carries the P3P covariance, `led_initial_guess`);
    robust: the inter-robot registration is `robust_register` with the
    `acceptance` checks (False: the multi-scale `refine` from the guess, no checks)."""

    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    acceptance: AcceptanceConfig = field(default_factory=AcceptanceConfig)
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    session: SessionConfig = field(default_factory=SessionConfig)
    odometry_sigmas: tuple[float, float] = (np.deg2rad(0.3), 0.01)
    pixel_sigma: float = 0.5
    p3p_method: str = "lambdatwist"
    p3p_gate: float = 50.0
    map_voxel: float = 0.03
    anchor_sigma: float = 1e-4
    build_map: bool = True  # False: skip step 5 (benchmarks of the transform only)
    scan_matching: bool = True  # False: between-factors straight from KISS-ICP with odometry_sigmas
    guess_sigma: tuple[float, float] = (np.deg2rad(5.0), 0.1)
    robust: bool = True


@dataclass(frozen=True)
class LedObservations:
    """The ceiling camera's view of the ground robot's LEDs. pixels (F,3,2), NaN where an LED is
    not seen; leds (3,3) LED positions in the ground LiDAR frame; T_ceiling_camera (4,4)."""

    camera: PinholeCamera
    leds: np.ndarray
    T_ceiling_camera: np.ndarray
    pixels: np.ndarray

    def __post_init__(self):
        px = np.asarray(self.pixels, dtype=float)
        if px.ndim != 3 or px.shape[1:] != (3, 2):
            raise ValueError(f"LedObservations.pixels must be (F,3,2), got {px.shape}")
        if np.asarray(self.leds).shape != (3, 3):
            raise ValueError(
                f"LedObservations.leds must be (3,3), got {np.asarray(self.leds).shape}"
            )
        if np.asarray(self.T_ceiling_camera).shape != (4, 4):
            raise ValueError("LedObservations.T_ceiling_camera must be 4x4")
        object.__setattr__(self, "pixels", px)


@dataclass(frozen=True)
class FusionInput:
    """Synchronized scan sequences (frame k of both robots at times[k]) in each LiDAR's frame,
    plus LED observations or a hint T_G0_C0 (4,4) for the inter-robot transform (one of the two);
    hint_sigma: optional 1-sigma (rot [rad], trans [m]) of the hint."""

    times: np.ndarray
    ground_scans: list
    ceiling_scans: list
    leds: LedObservations | None = None
    hint: np.ndarray | None = None
    hint_sigma: tuple[float, float] | None = None

    def __post_init__(self):
        t = np.asarray(self.times, dtype=float)
        if t.ndim != 1 or len(t) == 0:
            raise ValueError(
                f"FusionInput.times must be a non-empty (F,) array, got shape {t.shape}"
            )
        if not np.isfinite(t).all() or np.any(np.diff(t) <= 0):
            raise ValueError("FusionInput.times must be finite and strictly increasing")
        for name in ("ground_scans", "ceiling_scans"):
            if len(getattr(self, name)) != len(t):
                raise ValueError(
                    f"FusionInput.{name}: {len(getattr(self, name))} scans for {len(t)} times"
                )
        if self.leds is not None and len(self.leds.pixels) != len(t):
            raise ValueError(
                f"FusionInput.leds: {len(self.leds.pixels)} camera frames for {len(t)} times"
            )
        if (self.leds is None) == (self.hint is None):
            raise ValueError(
                "FusionInput: give LED observations or a relative pose hint for the inter-robot "
                "guess (exactly one of them)"
            )
        if self.hint is not None and (
            np.shape(self.hint) != (4, 4) or not np.isfinite(self.hint).all()
        ):
            raise ValueError("FusionInput.hint must be a finite 4x4 transform")
        if self.hint_sigma is not None and (
            np.shape(self.hint_sigma) != (2,) or not (np.asarray(self.hint_sigma) > 0).all()
        ):
            raise ValueError(
                f"FusionInput.hint_sigma must be (rot [rad], trans [m]) > 0, got {self.hint_sigma}"
            )
        object.__setattr__(self, "times", t)


@dataclass(frozen=True)
class GuessResult:
    """Inter-robot initial guess T_G0_C0 from the LEDs: frames used, candidates per frame, whether
    the tracker committed (locked), the posterior of the chosen candidate at the last frame, and
    per-frame candidate sets (camera poses in G_k, with covariances) kept for the P3P factors;
    covariance: 6x6 (right perturbation of T_G0_C0) from the chosen P3P candidate's first-order
    covariance and the odometry between C_0 / G_0 and that frame (`guess_covariance`)."""

    T_g0_c0: np.ndarray
    frames: np.ndarray
    n_candidates: np.ndarray
    locked: bool
    probability: float
    candidates: dict
    seconds: float
    skipped_frames: int
    covariance: np.ndarray


@dataclass(frozen=True)
class FusionResult:
    poses: dict  # robot index -> (F,4,4) optimized LiDAR poses in G_0
    odometry: dict  # robot index -> OdometryResult
    T_g0_c0: np.ndarray  # optimized inter-robot transform
    guess: np.ndarray  # initial guess handed to ICP
    guess_info: GuessResult | None
    registration: Registration
    n_p3p_factors: int
    map_points: np.ndarray  # (M,3) fused map in G_0
    map_labels: np.ndarray  # (M,) robot index of every point
    timings: dict
    graph_error: tuple[float, float]  # (initial, final)
    outliers_removed: dict = field(default_factory=dict)
    decision: RegistrationDecision | None = None  # robust_register's candidates and checks


class FusionRejected(Exception):
    """The inter-robot registration failed its acceptance checks: "not fused". Carries the
    decision (every candidate, every check) and the initial guess."""

    def __init__(self, decision: RegistrationDecision, guess: np.ndarray, guess_info=None):
        super().__init__("not fused: " + "; ".join(decision.reasons))
        self.decision, self.guess, self.guess_info = decision, guess, guess_info


# ----------------------------------------------------------------------------- P3P front-end


def led_candidates(leds: LedObservations, times: np.ndarray, cfg: FusionConfig):
    """P3P candidate sets of every camera frame with all three LEDs (camera poses in G_k) and
    their first-order covariances. Returns ({frame: CandidateSet}, skipped frame count)."""
    from graphloc.geometry.resection import resection_covariance

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


# ----------------------------------------------------------------------------- pipeline


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
        GROUND: [prepare(s, cfg.registration) for s in inp.ground_scans[:n_prep]],
        CEILING: [prepare(s, cfg.registration) for s in inp.ceiling_scans[:n_prep]],
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
    n_p3p = 0
    if guess_info is not None:
        extra = p3p_factors(
            guess_info,
            np.asarray(inp.leds.T_ceiling_camera, dtype=float),
            init_poses[GROUND],
            init_poses[CEILING],
            cfg.p3p_gate,
        )
        for fac in extra:
            graph.add(fac)
        n_p3p = len(extra)
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
        pcd, outliers[ROBOT_NAMES[r]] = denoise(
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
        n_p3p,
        np.concatenate(pts),
        np.concatenate(labels),
        timings,
        errors,
        outliers,
        decision,
    )
