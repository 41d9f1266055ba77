"""The option trees of map fusion (light: no Open3D or GTSAM): `FusionConfig`, the pipeline's
settings (the `[fusion]` tables; its parts are `graphloc.mapping.config`'s, the tracker's and
the session's), and `FuseMapsOptions`, the command-line options and `--config FILE.toml` keys
of `graphloc fuse-maps` / `demo` (`graphloc.config.add_config_arguments` / `config_from_args`):

    rate = 10.0                     # top level: the options of the command line
    [fusion]
    guess_sigma = [0.0873, 0.1]     # 1-sigma of a hint given without its own: rot [rad], m
    [fusion.registration]           # graphloc.mapping.registration.RegistrationConfig
    voxel = 0.03
    [fusion.acceptance]             # graphloc.mapping.acceptance.AcceptanceConfig
    min_inlier_ratio = 0.65
"""

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


@config_dataclass
class FuseMapsOptions:
    hint: str | None = setting(
        None,
        description="with --ground: T_G0_C0 as 'x y z qx qy qz qw' or 16 numbers (row-major)",
    )
    hint_sigma: str | None = setting(
        None,
        description="1-sigma of --hint: 'DEG M'; unset: the config's fusion.guess_sigma",
    )
    p3p: str | None = setting(
        None,
        description="with --ground: camera + LED setup JSON with an LED pixel CSV (inputs.py)",
    )
    rate: float = setting(
        10.0, gt=0.0, le=1000.0, description="frame rate of --ground / --ceiling [Hz]"
    )
    variant: str = setting(
        "furnished",
        description="simulated room variant (furnished, empty, rectangular, low_overlap)",
    )
    seed: int = setting(0, ge=0, le=2**32 - 1, description="simulated room: scenario seed")
    frames: int = setting(10, ge=1, le=1000, description="simulated room: frames per robot")
    mcap: str | None = setting(
        None,
        description="also write the fused map and trajectories as MCAP",
    )
    rerun: str | None = setting(None, description="also write a Rerun recording (.rrd)")
    fusion: FusionConfig = field(default_factory=FusionConfig)

    def __post_init__(self):
        if self.hint_sigma is not None and self.hint is None:
            raise ValueError("FuseMapsOptions.hint_sigma needs hint (--hint-sigma needs --hint)")
        if self.hint is not None and self.p3p is not None:
            raise ValueError("FuseMapsOptions: give hint or p3p, not both (--hint / --p3p)")
