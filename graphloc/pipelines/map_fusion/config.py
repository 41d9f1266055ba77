"""`FusionConfig`: the settings of ground + ceiling map fusion (seed 004, `map_fusion.fusion`),
the `[fusion]` tables of `fuse-maps` / `demo`; light (no Open3D or GTSAM: the command line's
options derive from it). Its parts are the scan algorithms' settings (`graphloc.mapping.config`),
the tracker's (`graphloc.hypotheses.config`) and the session's (`graphloc.session_config`)."""

from __future__ import annotations

import math
from dataclasses import field

from graphloc.config_schema import config_dataclass, setting
from graphloc.hypotheses.config import TrackerConfig
from graphloc.mapping.config import AcceptanceConfig, OdometryConfig, RegistrationConfig
from graphloc.session_config import SessionConfig


@config_dataclass
class FusionConfig:
    """odometry_sigmas: per-frame KISS-ICP increment sigmas (rot [rad], trans [m]); pixel_sigma:
    LED pixel noise [px] for the P3P covariances; p3p_outlier_d2: Mahalanobis^2 from the estimate
    beyond which a camera frame's P3P max-mixture takes its null component (an outlier frame;
    `led_guess.p3p_factors`);
    guess_sigma: 1-sigma (rot [rad], trans [m]) of a hint given without its own (the LED
    tracker's guess carries the P3P covariance, `led_initial_guess`);
    robust: the inter-robot registration is `robust_register` with the
    `acceptance` checks (False: the multi-scale `refine` from the guess, no checks)."""

    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    acceptance: AcceptanceConfig = field(default_factory=AcceptanceConfig)
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    session: SessionConfig = field(default_factory=SessionConfig)
    odometry_sigmas: tuple[float, float] = (math.radians(0.3), 0.01)
    pixel_sigma: float = setting(0.5, gt=0.0)
    p3p_outlier_d2: float = setting(50.0, gt=0.0)
    map_voxel: float = setting(0.03, gt=0.0)
    anchor_sigma: float = setting(1e-4, gt=0.0)
    build_map: bool = True  # False: skip step 5 (benchmarks of the transform only)
    scan_matching: bool = True  # False: between-factors straight from KISS-ICP with odometry_sigmas
    guess_sigma: tuple[float, float] = (math.radians(5.0), 0.1)
    robust: bool = True
