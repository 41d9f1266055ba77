"""Types shared by the engines and the checkout's baselines: a candidate tracker's update
(`Odometry`, `Decision`; seed 000 Sec. V, seed 004 Sec. II-C) and one frame of seed 003
(`FrameInput`, `TeammateObservation`, `MotionNoise`; Sec. II-B, eq. 8)."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.odometry import check_covariance


@dataclass(frozen=True)
class Odometry:
    """Relative pose of the tracked frame since the previous update, T_{t-1}^-1 T_t (in the
    frame of the earlier pose), with its 6x6 covariance (GTSAM Pose3 tangent order)."""

    relative: gtsam.Pose3
    covariance: np.ndarray

    def __post_init__(self):
        if not isinstance(self.relative, gtsam.Pose3):
            raise ValueError(
                f"Odometry.relative must be gtsam.Pose3, got {type(self.relative).__name__}"
            )
        m = self.relative.matrix()
        if not np.isfinite(m).all():
            raise ValueError("Odometry.relative contains NaN/inf")
        cov = np.asarray(self.covariance, dtype=float)
        if cov.shape != (6, 6):
            raise ValueError(f"Odometry.covariance must be (6,6), got {cov.shape}")
        check_covariance(cov, "Odometry.covariance")
        object.__setattr__(self, "covariance", cov)


@dataclass(frozen=True)
class Decision:
    """Output of one update, shared by the tracker and the baselines (the team graph's record
    of what became of a candidate set, made from it, is `team_graph.candidates.SetOutcome`).

    probabilities (K,): posterior that candidate k of this frame is the genuine one (may sum
    to < 1: the rest is on "none of them", e.g. a coasting track). committed: index of the
    committed candidate in this frame, or -1 (nothing committed, or the committed track has
    no candidate this frame). locked: a mode is committed. pose: estimate of the committed
    track, else of the most probable one (None before any candidate). relocalized: this frame
    released a committed mode."""

    probabilities: np.ndarray
    committed: int
    locked: bool
    pose: gtsam.Pose3 | None
    relocalized: bool = False


def check_frame(candidates, odometry, first: bool, last_time: float | None, who: str) -> None:
    """Shared input validation of the trackers: types, odometry presence, monotonic time."""
    if not isinstance(candidates, CandidateSet):
        raise ValueError(
            f"{who}: candidates must be a CandidateSet, got {type(candidates).__name__}"
        )
    if not first and odometry is None:
        raise ValueError(
            f"{who}: odometry is required after the first frame (time={candidates.time})"
        )
    if odometry is not None and not isinstance(odometry, Odometry):
        raise ValueError(f"{who}: odometry must be an Odometry, got {type(odometry).__name__}")
    if last_time is not None and not candidates.time > last_time:
        raise ValueError(
            f"{who}: time going backwards or repeated: {candidates.time} after {last_time}"
        )


@dataclass(frozen=True)
class TeammateObservation:
    """The teammate's base in the camera frame. candidates: the circle poses T_cam_base (both
    solutions, z = disk normal) with candidate_covariance (3,3) [m^2], the first-order noise
    of one candidate's centre. centre (3,), covariance (3,3): their moment-matched Gaussian
    (the 'moment_matched_centre' baseline); pixel (2,): its projection (the robot tracker's
    special feature point of seed II-B). disk_covariance (5,5), optional: the full covariance
    of (centre x, y, z [m] in the camera frame; normal tilt a, b [rad] towards the disk's x and
    y axes, n + a x + b y) when it is known (e.g. a Cramér-Rao bound,
    `benchmarks.seed003_measures.disk_information`); it then replaces candidate_covariance and
    CooperativeSfmConfig.normal_sigma in the max-mixture, correlations included."""

    centre: np.ndarray
    covariance: np.ndarray
    pixel: np.ndarray
    n_candidates: int
    candidate_spread: float  # max distance of a candidate centre from the mean [m]
    candidate_separation: float = 0.0  # max Mahalanobis distance between two candidate centres
    candidates: CandidateSet | None = None
    candidate_covariance: np.ndarray | None = None
    disk_covariance: np.ndarray | None = None


@dataclass(frozen=True)
class FrameInput:
    """Everything the estimators get for one frame (the same for the graph and the EKF).
    features: the frame's KLT tracks, `graphloc.vision.features.FrameFeatures` (ids (N,),
    pixels (N,2); the front-end's type, named here without importing it: the front-ends
    import this module); camera_moved / teammate_moved: whether that robot moved since the
    previous frame (the robots move and stop in turns and know when they move);
    teammate_odometry [m], std [m]: its own odometry distance since the previous frame (0 when
    it stood still)."""

    time: float
    features: "FrameFeatures"  # noqa: F821  (graphloc.vision.features)
    teammate: TeammateObservation | None
    camera_moved: bool
    teammate_moved: bool
    teammate_odometry: float = 0.0
    teammate_odometry_std: float = 0.0


@dataclass(frozen=True)
class MotionNoise:
    """Process noise per frame (seed eq. 8, F = identity): rotation [rad] and translation [m]
    sigmas when the camera robot moved, and when it stood still. Shared with the EKF."""

    rot: float = 0.03
    trans: float = 0.02
    still_rot: float = 1e-3
    still_trans: float = 1e-3

    def sigmas(self, moved: bool) -> tuple[float, float]:
        return (self.rot, self.trans) if moved else (self.still_rot, self.still_trans)
