"""The types of ground + ceiling map fusion (seed 004; the pipeline is `map_fusion.fusion`):
its configuration (`FusionConfig`, defined in the light `map_fusion.options`), inputs
(synchronized scans, plus the ceiling camera's view of the ground robot's LEDs or a relative
pose hint), the LED initial guess (`GuessResult`), the result, and `FusionRejected` ("not
fused"). Frames: G_k / C_k are the ground / ceiling LiDAR at frame k; everything is expressed
in G_0."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.mapping.acceptance import RegistrationDecision
from graphloc.mapping.registration import Registration

GROUND, CEILING = 0, 1


ROBOT_NAMES = {GROUND: "ground", CEILING: "ceiling"}


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
    n_p3p_factors: int  # max-mixtures of P3P candidates (one per camera frame with a set)
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
