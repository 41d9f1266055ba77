"""Settings of the cooperative SfM graph (benchmarks.cooperative_sfm), the keys'
robot indices, and the checks a frame passes before it enters the graph."""

from __future__ import annotations

from dataclasses import field

from typing import Literal
import gtsam
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from graphloc.factors.mixture import check_covariances
from graphloc.factors.robust import Kernel
from graphloc.seams import FrameInput, MotionNoise
from graphloc.session import SessionConfig

CAMERA_ROBOT, TEAMMATE = 0, 1
TEAMMATE_MODELS = ("max_mixture", "moment_matched_centre")
WORLD_UP = np.array([0.0, -1.0, 0.0])  # OpenCV world (camera 0, level): y points down


@config_dataclass
class CooperativeSfmConfig:
    """pixel_sigma [px]: KLT noise (seed III: variance 1); kernel: robust kernel on the
    projections; motion: process noise; first_pose_sigma: gauge prior (rad and m);
    feature_prior_depth [m], feature_prior_sigma [m]: the KLT points' initial position (common
    depth on the first ray; seed III: background at 260 cm) and its std (the same settings as
    the seed-003 EKF);
    teammate_still_sigma [m]: zero-motion between-factor of a teammate that stood still (and
    [rad] for its attitude in the max-mixture model);
    teammate_model: 'max_mixture' (default: each sighting's circle candidates as a max-mixture
    on the relative pose camera -> base) or 'moment_matched_centre' (baseline: the candidates'
    centres moment-matched into one Gaussian on a Point3, normals unused);
    normal_sigma [rad]: disk-normal noise of one candidate, tuned on crawler-pair seeds
    100-107 (not used by the benchmark): the genuine normal carries a bias shared by the
    frames, and a tighter sigma made the camera attitude follow it (larger x error at
    N = 10) without improving the scale; the false normal stays many sigmas away;
    circle_yaw_sigma [rad]: rotation about the normal, unobservable from a circle (loose);
    upright_sigma [rad]: the teammate stands on the ground -- its base's y axis (in the disk
    plane, circle convention of `graphloc.vision.circle`) is vertical, i.e. world -y (world =
    camera 0, level), up to ground roughness and the normal's bias; one prior per pose the
    teammate stands in (tuned on seeds 100-103: a tighter prior pulls the camera pitch);
    session: the engine (mode batch / online; online default: two extra iSAM2 iterations per
    frame, since new landmarks start at the common depth and one step is not enough, with the
    dog-leg step: with the refined rim's tight depth noise the undamped Gauss-Newton step
    oscillated with period 2 on crawler-pair seed 9, N = 20, which the dog-leg step does not)."""

    pixel_sigma: float = setting(1.0, gt=0.0)
    kernel: Kernel = Kernel("huber", 1.345)
    motion: MotionNoise = MotionNoise()
    first_pose_sigma: float = setting(1e-4, gt=0.0)
    feature_prior_depth: float = setting(2.6, gt=0.0)
    feature_prior_sigma: float = setting(1.0, gt=0.0)
    teammate_still_sigma: float = setting(1e-3, gt=0.0)
    teammate_model: Literal[TEAMMATE_MODELS] = "max_mixture"
    normal_sigma: float = setting(0.03, gt=0.0)
    circle_yaw_sigma: float = setting(1.0, gt=0.0)
    upright_sigma: float = setting(0.05, gt=0.0)
    session: SessionConfig = field(
        default_factory=lambda: SessionConfig(
            relinearize_threshold=0.01, extra_updates=2, isam2_optimizer="dogleg"
        )
    )


def pose_noise(rot: float, trans: float):
    return gtsam.noiseModel.Diagonal.Sigmas(np.array([rot] * 3 + [trans] * 3))


def check_frame(frame: FrameInput, last_time: float, teammate_model: str) -> None:
    """ValueError naming the frame's time and the field unless `frame` is a FrameInput after
    `last_time` with (M,) feature ids and (M,2) pixels, a finite teammate odometry when the
    teammate moved, a finite teammate observation with valid covariances and, for the
    max-mixture model, the circle candidates."""
    if not isinstance(frame, FrameInput):
        raise ValueError(
            f"CooperativeSfm.add_frame: expected FrameInput, got {type(frame).__name__}"
        )
    if not frame.time > last_time:
        raise ValueError(f"CooperativeSfm.add_frame: time {frame.time} does not follow {last_time}")
    ids = np.asarray(frame.features.ids)
    pixels = np.asarray(frame.features.pixels, dtype=float)
    if ids.ndim != 1 or pixels.shape != (len(ids), 2):
        raise ValueError(
            f"CooperativeSfm.add_frame: frame {frame.time}: features ids {ids.shape} / pixels "
            f"{pixels.shape} must be (M,) / (M,2)"
        )
    if frame.teammate_moved and not (
        np.isfinite(frame.teammate_odometry)
        and frame.teammate_odometry >= 0
        and np.isfinite(frame.teammate_odometry_std)
        and frame.teammate_odometry_std > 0
    ):
        raise ValueError(
            f"CooperativeSfm.add_frame: frame {frame.time}: teammate moved with odometry "
            f"{frame.teammate_odometry} +- {frame.teammate_odometry_std}; need a finite "
            f"distance >= 0 and std > 0"
        )
    if frame.teammate is not None and not (
        np.isfinite(frame.teammate.centre).all() and np.isfinite(frame.teammate.covariance).all()
    ):
        raise ValueError(
            f"CooperativeSfm.add_frame: frame {frame.time}: teammate observation has NaN/inf"
        )
    if (
        frame.teammate is not None
        and teammate_model == "max_mixture"
        and (frame.teammate.candidates is None or frame.teammate.candidate_covariance is None)
    ):
        raise ValueError(
            f"CooperativeSfm.add_frame: frame {frame.time}: teammate_model 'max_mixture' needs "
            f"the circle candidates and their centre covariance in the TeammateObservation"
        )
    if frame.teammate is not None and frame.teammate.candidate_covariance is not None:
        check_covariances(
            np.asarray(frame.teammate.candidate_covariance, float).reshape(1, 3, 3),
            f"CooperativeSfm.add_frame: frame {frame.time}: teammate candidate_covariance",
        )
    if frame.teammate is not None and frame.teammate.disk_covariance is not None:
        if np.shape(frame.teammate.disk_covariance) != (5, 5):
            raise ValueError(
                f"CooperativeSfm.add_frame: frame {frame.time}: teammate disk_covariance "
                f"must be (5,5), got {np.shape(frame.teammate.disk_covariance)}"
            )
        check_covariances(
            np.asarray(frame.teammate.disk_covariance, float).reshape(1, 5, 5),
            f"CooperativeSfm.add_frame: frame {frame.time}: teammate disk_covariance",
        )
