"""Settings of the team graph (`GraphConfig`), the run's precision that iSAM2's thresholds
follow, and the online lag policy."""

from __future__ import annotations


from typing import Literal
import gtsam
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from graphloc.factors.odometry import VelocityNoise
from graphloc.factors.robust import Kernel, KernelPolicy
from graphloc.hypotheses import TrackerConfig
from graphloc.pipelines.team_graph.options import DEFAULT_LAG
from graphloc.run import TeamRun
from graphloc.session import SessionConfig

COARSE_PRECISION = 0.1  # [m, rad] scale of a run without pose measurements (wheels, range-bearing)
FINE_PRECISION = 0.002  # the finest precision iSAM2's thresholds follow
ANCHOR_BASE = (
    100_000_000  # landmark_key(ANCHOR_BASE + j): j-th anchor of a known landmark (bearing, range)
)


FEATURE_BASE = 200_000_000  # landmark_key(FEATURE_BASE + j): the point of the j-th feature track


@config_dataclass
class GraphConfig:
    """The team graph's settings: the wheel robots' pose grid (`keyframe_dt` [s]) and how far from a
    pose another robot's measurement may be (`sync_tolerance` [s]); which measurements to use;
    robust kernels by factor type; prior sigmas as (rot [rad], trans [m]); the candidate tracker and
    its rule (a set is decided when the committed track's candidate, with those of the same pose,
    has a posterior of at least `decision_threshold`; a marker-pixel stream undecided after
    `guess_after_sets` sets places its observer by the tracker's guess); the session's settings
    (iSAM2 thresholds None: from `run_precision`)."""

    keyframe_dt: float = setting(0.25, gt=0.0)
    sync_tolerance: float = setting(0.02, gt=0.0)
    use_landmarks: bool = True
    use_inter_robot: bool = True
    landmark_priors: bool = True
    anchor_known_landmarks: bool = True  # a known landmark per observation, not one variable
    kernels: KernelPolicy = KernelPolicy(
        {
            "landmark": Kernel("cauchy", 2.0),
            "inter_robot": Kernel("cauchy", 2.0),
            "candidate": Kernel("cauchy", 1.0),
            "projection": Kernel("huber", 1.345),
        }
    )
    velocity_noise: VelocityNoise = VelocityNoise(density_v=0.01, density_w=0.05)
    initial_sigma: tuple = (0.02, 0.05)
    static_sigma: tuple = (1e-4, 1e-4)
    surface_sigma: float = setting(0.005, gt=0.0)
    marker_sigma: float = setting(0.001, gt=0.0)
    landmark_prior_floor: float = setting(0.01, gt=0.0)
    unknown_motion_sigma: tuple = (3.0, 100.0)
    tracker: TrackerConfig = TrackerConfig()
    decision_threshold: float = setting(0.8, ge=0.5, lt=1.0)  # see the docstring
    guess_after_sets: int = setting(5, ge=1)  # see the docstring
    downweight_threshold: float = setting(0.1, ge=0.0)
    relinearize_threshold: float | None = setting(None, gt=0.0)
    relinearize_translation: float | None = setting(None, ge=0.0)  # see `session_config`
    relinearize_skip: int = setting(10, ge=1)
    wildfire_threshold: float | None = setting(None, gt=0.0)
    extra_updates: int | None = setting(None, ge=0)
    lm_max_iterations: int = setting(100, ge=1)
    # [m] seed 003 III: KLT points start at the background (260 cm)
    feature_depth: float = setting(2.6, gt=0.0)
    # [m] and its std (where the camera's params give none)
    feature_depth_sigma: float = setting(1.0, gt=0.0)
    # inter-robot scan registration (`live.event_scans`): graphloc.mapping.registration's
    # RegistrationConfig / AcceptanceConfig, None = their defaults
    registration: object = None
    acceptance: object = None
    scan_hint_sigma: tuple = (0.05, 0.1)  # (rot [rad], trans [m]) of registrations between
    # placed robots, started from their current initial poses
    # online: fixed-lag window [s] (None / 0: full smoothing)
    lag: float | None = setting(None, ge=0.0)
    marginalize_every: float = 4.0  # [s] fixed lag: old variables leave in batches this long
    # iSAM2's factorization: CHOLESKY (fast); QR where Cholesky finds the system indeterminate
    # (`solve` retries an online solve with it)
    factorization: Literal["CHOLESKY", "QR"] = "CHOLESKY"

    def __post_init__(self):
        for name in ("initial_sigma", "static_sigma", "unknown_motion_sigma", "scan_hint_sigma"):
            v = getattr(self, name)
            if len(v) != 2 or not all(np.isfinite(s) and s > 0 for s in v):
                raise ValueError(f"GraphConfig.{name} must be 2 numbers > 0 (rot, trans), got {v}")

    def session_config(
        self, mode: str, precision: float = COARSE_PRECISION, camera_graph: bool = False
    ) -> SessionConfig:
        """Session settings; iSAM2's thresholds, unless set, follow the run's `precision`
        (`run_precision`); a graph with feature tracks or max-mixtures (`camera_graph`) relinearizes
        at every update with the dog-leg step (docs/design_team_graph.md, "iSAM2 settings")."""
        relin = (
            self.relinearize_threshold
            if self.relinearize_threshold is not None
            else 0.5 * precision
        )
        skip = 1 if camera_graph else self.relinearize_skip
        trans = self.relinearize_translation
        if trans is None:
            trans = 0.2 * precision if precision >= COARSE_PRECISION and not camera_graph else 0.0
        wildfire = (
            self.wildfire_threshold if self.wildfire_threshold is not None else 0.1 * precision
        )
        extra = (
            self.extra_updates
            if self.extra_updates is not None
            else (2 if precision < COARSE_PRECISION else 0)
        )
        return SessionConfig(
            mode=mode,
            lm_max_iterations=self.lm_max_iterations,
            relinearize_threshold=relin,
            relinearize_translation=trans,
            relinearize_skip=skip,
            wildfire_threshold=wildfire,
            extra_updates=extra,
            partial_relinearization_check=True,
            isam2_optimizer="dogleg" if camera_graph else "gauss_newton",
            marginalize_every=self.marginalize_every,
            factorization=self.factorization,
        )


def cov6(sig: tuple) -> np.ndarray:
    return np.diag([sig[0] ** 2] * 3 + [sig[1] ** 2] * 3)


def adjoint_cov(T: gtsam.Pose3, cov: np.ndarray) -> np.ndarray:
    A = T.AdjointMap()
    return A @ cov @ A.T


def run_precision(run: TeamRun) -> float:
    """The scale [m, rad] of the run's estimates that iSAM2's thresholds follow: FINE_PRECISION with
    candidate sets, else the median translation std of one relative-pose step (within FINE and
    COARSE), else COARSE_PRECISION."""
    if run.observations:
        return FINE_PRECISION
    steps = [np.sqrt(np.trace(m.covariance[3:, 3:]) / 3) for m in run.motions]
    if steps:
        return float(np.clip(np.median(steps), FINE_PRECISION, COARSE_PRECISION))
    return COARSE_PRECISION


def default_lag(run, config: GraphConfig) -> float:
    """The online lag when none is given: DEFAULT_LAG unless a variable must outlive the window -- a
    static robot's one pose, a landmark estimated as one variable (SLAM) --, then 0 (full
    smoothing)."""
    static = any(r.static for r in run.robots)
    slam = config.use_landmarks and not (
        config.landmark_priors and run.landmarks_known and config.anchor_known_landmarks
    )
    return 0.0 if static or slam else DEFAULT_LAG
