"""Cooperative motion and structure from one camera with a teammate robot as the scale anchor
(seed 003, 003_8db27855ce2d5f68.txt: section II "robot tracker" gives the
3D position of the teammate's base centre from its ellipse, II-B the motion estimator tracks
KLT features; the robots move and stop in turns) as ONE factor graph solved by `Session`
(batch Levenberg-Marquardt or online iSAM2, same factors):

  x(0,t)  camera pose of the moving robot at frame t (Pose3, world = camera 0, OpenCV axes)
  x(1,t)  the teammate's base disk at frame t (Pose3: origin = centre, z = disk normal), for
          the frames it is seen (Point3 centre in the 'moment_matched_centre' baseline)
  l(j)    KLT feature j (Point3)

  PriorFactorPose3 on x(0,0)                 seed III: the robot starts at the origin (zero
                                             initial covariance of T and omega)
  BetweenFactorPose3 x(0,t-1) -> x(0,t)      seed eq. 8 with F = identity: constant-position
                                             motion model with the process noise Q
  GenericProjectionFactorCal3_S2 x(0,t), l(j)  seed eq. 14: KLT pixels (Huber kernel)
  max-mixture of BetweenFactorPose3          seed eqs. 1-4: the two circle poses T_cam_base of the
    x(0,t) -> x(1,t), one per candidate      sighting (centre + normal; yaw about the normal loose),
                                             Olson & Agarwal max-mixture (factors.mixture), weights
                                             from the candidate scores
  AttitudeFactorPose3 on x(1,t)              the teammate stands on the ground: base y axis up
                                             (one per stance)
  BetweenFactorPose3 x(1,s) -> x(1,t)        the teammate stood still (zero motion)
  RangeFactorPose3 x(1,s) -> x(1,t)          the teammate moved (straight) by its odometry distance
  PriorFactorPoint3 on l(j)                  seed III: KLT points start "all at the same
                                             position" with a high covariance -- here on their
                                             first ray at one common depth, std
                                             feature_prior_sigma (the EKF's initial state)

Every KLT track becomes a landmark at its first observation, so rotation is constrained from
the first frames on and no landmark is ever undetermined (a point pushed behind a camera by an
undamped iSAM2 step, where GenericProjectionFactor gives no information, keeps its prior;
without the prior iSAM2 raised IndeterminantLinearSystem on crawler-pair). Projection factors
with explicit landmarks rather than SmartProjectionPose3Factor: a smart factor grows with its
track, and Session (append-only `add`) cannot tell iSAM2 that an added factor changed. Batch
and online see the same factors, added frame by frame through one `Session`.

The circle front-end (`graphloc.vision.circle`) returns BOTH poses of the base (the ellipse
cannot tell them apart). Their centres nearly coincide but their normals differ widely (the
front-end table of docs/results_seed003.md measures both; the false normal also tilts out of
the vertical plane and drifts as the robots move). Both enter as a max-mixture: the genuine
candidate is the one consistent with the other sightings (tied by the teammate's zero-motion
factors) and with its upright attitude, so the graph picks it per frame
(`CooperativeSfm.active_components`, `SfmRun.active_final` / `active_causal`) and the normal
constrains the camera attitude too. In online mode the choice is re-evaluated only when iSAM2
relinearizes x(0,t) or x(1,t) (see `factors.mixture.MaxMixture`); the session default
relinearize_threshold 0.01 with two extra updates per frame. The moment-matched Gaussian of the
candidate centres on a Point3 (normals unused) stays as the baseline
teammate_model='moment_matched_centre'. A Python CustomFactor cannot be pickled by GTSAM, so
`Session.save` works only for that baseline.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.config import check
from graphloc.factors.mixture import (
    MaxMixture,
    check_covariances,
    component_factors,
    max_mixture_factor,
    mixture_weights,
)
from graphloc.factors.range_bearing import landmark_factor_3d
from graphloc.factors.robust import Kernel, robust_noise
from graphloc.keys import landmark_key, pose_key
from graphloc.seams import FrameInput, MotionNoise
from graphloc.session import Session, SessionConfig

CAMERA_ROBOT, TEAMMATE = 0, 1
TEAMMATE_MODELS = ("max_mixture", "moment_matched_centre")
WORLD_UP = np.array([0.0, -1.0, 0.0])  # OpenCV world (camera 0, level): y points down


@dataclass(frozen=True)
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

    pixel_sigma: float = 1.0
    kernel: Kernel = Kernel("huber", 1.345)
    motion: MotionNoise = MotionNoise()
    first_pose_sigma: float = 1e-4
    feature_prior_depth: float = 2.6
    feature_prior_sigma: float = 1.0
    teammate_still_sigma: float = 1e-3
    teammate_model: str = "max_mixture"
    normal_sigma: float = 0.03
    circle_yaw_sigma: float = 1.0
    upright_sigma: float = 0.05
    session: SessionConfig = field(
        default_factory=lambda: SessionConfig(
            relinearize_threshold=0.01, extra_updates=2, isam2_optimizer="dogleg"
        )
    )

    def __post_init__(self):
        check(
            self,
            positive=(
                "pixel_sigma",
                "first_pose_sigma",
                "feature_prior_depth",
                "feature_prior_sigma",
                "teammate_still_sigma",
                "normal_sigma",
                "circle_yaw_sigma",
                "upright_sigma",
            ),
            choices={"teammate_model": TEAMMATE_MODELS},
        )


def disk_pose_covariance(
    R: np.ndarray, disk_covariance: np.ndarray, yaw_sigma: float
) -> np.ndarray:
    """(K,6,6) covariances of circle poses T_cam_base (rotations R (K,3,3), z = normal) in
    GTSAM's Pose3 tangent (omega, v; base frame) from a (5,5) disk covariance over (centre in
    the camera frame, normal tilt a, b towards the disk's x, y axes), yaw_sigma [rad] about the
    normal: T Exp(omega, v) moves the centre by R v and the normal by omega_y x - omega_x y, so
    omega_x = -b, omega_y = a, v = R^T dc."""
    R = np.asarray(R, float).reshape(-1, 3, 3)
    J = np.zeros((len(R), 6, 5))
    J[:, 0, 4], J[:, 1, 3] = -1.0, 1.0
    J[:, 3:, :3] = np.transpose(R, (0, 2, 1))
    cov = np.einsum("kij,jl,kml->kim", J, np.asarray(disk_covariance, float).reshape(5, 5), J)
    cov[:, 2, 2] = yaw_sigma**2
    return cov


def _pose_noise(rot: float, trans: float):
    return gtsam.noiseModel.Diagonal.Sigmas(np.array([rot] * 3 + [trans] * 3))


class CooperativeSfm:
    """Frame-by-frame graph builder over one `Session` (see the module docstring).

    sfm = CooperativeSfm(camera, CooperativeSfmConfig(session=SessionConfig(mode="online")))
    for frame in frames:              # FrameInput
        pose = sfm.add_frame(frame)   # current camera pose estimate (gtsam.Pose3)
    values = sfm.session.estimate()
    """

    def __init__(
        self, camera: PinholeCamera, config: CooperativeSfmConfig = CooperativeSfmConfig()
    ):
        if camera.dist:
            raise ValueError(
                "CooperativeSfm: the camera must be undistorted (Cal3_S2 projection factors)"
            )
        self.camera = camera
        self.config = config
        self.session = Session(config.session)
        self.calibration = gtsam.Cal3_S2(camera.fx, camera.fy, 0.0, camera.cx, camera.cy)
        self._pixel_noise = robust_noise(
            gtsam.noiseModel.Isotropic.Sigma(2, config.pixel_sigma), config.kernel
        )
        self.admitted: set[int] = set()
        self.frame = -1
        self._last_time = -np.inf
        self._estimate = gtsam.Values()
        self._last_mate: int | None = None
        self._mate_distance = 0.0
        self._mate_variance = 0.0
        self._mate_moved = False
        self.online_positions: list[
            np.ndarray
        ] = []  # causal estimate of each frame's camera position
        self.history: list[
            np.ndarray
        ] = []  # at frame k: (k+1,3) estimated positions of frames 0..k
        self.skipped_pixels = 0  # non-finite feature pixels (counted, not used)
        self.mixtures: dict[
            int, MaxMixture
        ] = {}  # frame -> max-mixture of that sighting's candidates
        self.causal_active: dict[int, int] = {}  # frame -> active component when the frame arrived

    # ---- one frame -------------------------------------------------------------------------
    def add_frame(self, frame: FrameInput) -> gtsam.Pose3:
        if not isinstance(frame, FrameInput):
            raise ValueError(
                f"CooperativeSfm.add_frame: expected FrameInput, got {type(frame).__name__}"
            )
        if not frame.time > self._last_time:
            raise ValueError(
                f"CooperativeSfm.add_frame: time {frame.time} does not follow {self._last_time}"
            )
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
            np.isfinite(frame.teammate.centre).all()
            and np.isfinite(frame.teammate.covariance).all()
        ):
            raise ValueError(
                f"CooperativeSfm.add_frame: frame {frame.time}: teammate observation has NaN/inf"
            )
        if (
            frame.teammate is not None
            and self.config.teammate_model == "max_mixture"
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
        self._last_time = frame.time
        self.frame += 1
        k = self.frame
        x = pose_key(CAMERA_ROBOT, k)
        graph, values = (
            [],
            gtsam.Values(),
        )  # factors (and max-mixtures, kept whole so Session.save works)
        if k == 0:
            graph.append(
                gtsam.PriorFactorPose3(
                    x,
                    gtsam.Pose3(),
                    _pose_noise(self.config.first_pose_sigma, self.config.first_pose_sigma),
                )
            )
            guess = gtsam.Pose3()
        else:
            sig = self.config.motion.sigmas(frame.camera_moved)
            graph.append(
                gtsam.BetweenFactorPose3(
                    pose_key(CAMERA_ROBOT, k - 1), x, gtsam.Pose3(), _pose_noise(*sig)
                )
            )
            guess = self._camera_guess(frame, self._estimate.atPose3(pose_key(CAMERA_ROBOT, k - 1)))
        values.insert(x, guess)
        self._add_teammate(frame, k, guess, graph, values)
        finite = np.isfinite(pixels).all(axis=1)
        self.skipped_pixels += int((~finite).sum())
        ids, pixels = ids[finite], pixels[finite]
        new = np.array([i not in self.admitted for i in ids.tolist()], dtype=bool)
        if new.any():
            bearings, _ = self.camera.pixel_to_bearing(pixels[new])
            points = guess.transformFrom(
                (bearings / bearings[:, 2:3] * self.config.feature_prior_depth).T
            ).T
            prior = gtsam.noiseModel.Isotropic.Sigma(3, self.config.feature_prior_sigma)
            for j, point in zip(ids[new].tolist(), points.reshape(-1, 3)):
                values.insert(landmark_key(j), point)
                graph.append(gtsam.PriorFactorPoint3(landmark_key(j), point, prior))
                self.admitted.add(j)
        for j, uv in zip(ids.tolist(), pixels):
            graph.append(
                gtsam.GenericProjectionFactorCal3_S2(
                    gtsam.Point2(*uv), self._pixel_noise, x, landmark_key(j), self.calibration
                )
            )
        self.session.add(graph, values, time=frame.time)
        self._estimate = self.session.estimate()
        if k in self.mixtures:
            self.causal_active[k] = self.mixtures[k].active(self._estimate)
        pose = self._estimate.atPose3(x)
        self.online_positions.append(np.asarray(pose.translation()))
        self.history.append(
            np.array(
                [
                    self._estimate.atPose3(pose_key(CAMERA_ROBOT, i)).translation()
                    for i in range(k + 1)
                ]
            )
        )
        return pose

    def _add_teammate(self, frame: FrameInput, k: int, guess: gtsam.Pose3, graph, values) -> None:
        if k > 0 and frame.teammate_moved:
            self._mate_moved = True
            self._mate_distance += frame.teammate_odometry
            self._mate_variance += frame.teammate_odometry_std**2
        obs = frame.teammate
        if obs is None:
            return
        m = pose_key(TEAMMATE, k)
        prev = None if self._last_mate is None else pose_key(TEAMMATE, self._last_mate)
        if self.config.teammate_model == "max_mixture":
            self._add_teammate_mixture(obs, k, m, prev, guess, graph, values)
        else:
            self._add_teammate_centre(obs, k, m, prev, guess, graph, values)
        self._last_mate = k
        self._mate_distance, self._mate_variance, self._mate_moved = 0.0, 0.0, False

    def _add_teammate_centre(self, obs, k, m, prev, guess, graph, values) -> None:
        """Baseline 'moment_matched_centre': x(1,k) is a Point3 seen by BearingRangeFactor3D."""
        rng = float(np.linalg.norm(obs.centre))
        direction = obs.centre / rng
        # Unit3 bearing noise from the lateral covariance, range noise from the radial part
        lateral = np.trace(obs.covariance) - direction @ obs.covariance @ direction
        sigmas = (np.sqrt(max(lateral, 1e-18) / 2.0) / rng,) * 2 + (
            np.sqrt(direction @ obs.covariance @ direction),
        )
        graph.append(landmark_factor_3d(pose_key(CAMERA_ROBOT, k), m, direction, rng, sigmas))
        values.insert(m, guess.transformFrom(obs.centre))
        if prev is not None:
            if self._mate_moved:
                graph.append(
                    gtsam.RangeFactor3(
                        prev,
                        m,
                        self._mate_distance,
                        gtsam.noiseModel.Isotropic.Sigma(1, np.sqrt(self._mate_variance)),
                    )
                )
            else:
                graph.append(
                    gtsam.BetweenFactorPoint3(
                        prev,
                        m,
                        np.zeros(3),
                        gtsam.noiseModel.Isotropic.Sigma(3, self.config.teammate_still_sigma),
                    )
                )

    def _add_teammate_mixture(self, obs, k, m, prev, guess, graph, values) -> None:
        """'max_mixture': x(1,k) is the base's Pose3 (z = disk normal); the K circle candidates
        T_cam_base enter as a max-mixture (`factors.mixture.max_mixture_factor`) of
        BetweenFactorPose3(x(0,k), x(1,k), T_k), weights from the candidate scores, each with
        the centre covariance (rotated into the candidate frame) and normal_sigma on the
        normal -- or the observation's full disk_covariance --, circle_yaw_sigma about it;
        AttitudeFactorPose3 keeps the base upright."""
        cands = obs.candidates
        if len(cands) == 0:
            raise ValueError(
                f"CooperativeSfm: frame {k}: teammate observation with no circle candidates"
            )
        cfg = self.config
        cov = np.zeros((len(cands), 6, 6))
        if obs.disk_covariance is None:
            cov[:, :3, :3] = np.diag(
                [cfg.normal_sigma**2, cfg.normal_sigma**2, cfg.circle_yaw_sigma**2]
            )
            cov[:, 3:, 3:] = np.einsum(
                "kji,jl,klm->kim", cands.R, obs.candidate_covariance, cands.R
            )
        else:
            cov = disk_pose_covariance(cands.R, obs.disk_covariance, cfg.circle_yaw_sigma)
        components = component_factors(cands, m, pose_key(CAMERA_ROBOT, k), cov)
        if len(components) == 1:
            graph.append(components[0])
        else:
            mixture = max_mixture_factor(components, mixture_weights(cands))
            graph.append(mixture)
            self.mixtures[k] = mixture
        # initial guess (engine-side knowledge, never a choice the factor is bound to): a teammate
        # that stood still is where it was; after a move, the candidate whose normal is closest to
        # its previous normal (it crawls straight); at the first sighting the most upright one
        R_cam = guess.rotation().matrix()
        if prev is not None and not self._mate_moved:
            values.insert(m, self._estimate.atPose3(prev))
        else:
            if prev is None:
                score = np.einsum("ij,kj->ki", R_cam, cands.R[:, :, 1]) @ WORLD_UP
            else:
                previous_normal = self._estimate.atPose3(prev).rotation().matrix()[:, 2]
                score = np.einsum("ij,kj->ki", R_cam, cands.R[:, :, 2]) @ previous_normal
            values.insert(m, guess.compose(cands.poses()[int(np.argmax(score))]))
        if prev is None or self._mate_moved:  # a new stance on the ground
            graph.append(
                gtsam.AttitudeFactorPose3(
                    m,
                    gtsam.Unit3(WORLD_UP),
                    gtsam.noiseModel.Isotropic.Sigma(2, cfg.upright_sigma),
                    gtsam.Unit3(np.array([0.0, 1.0, 0.0])),
                )
            )
        if prev is not None:
            if self._mate_moved:
                graph.append(
                    gtsam.RangeFactorPose3(
                        prev,
                        m,
                        self._mate_distance,
                        gtsam.noiseModel.Isotropic.Sigma(1, np.sqrt(self._mate_variance)),
                    )
                )
            else:
                graph.append(
                    gtsam.BetweenFactorPose3(
                        prev,
                        m,
                        gtsam.Pose3(),
                        _pose_noise(cfg.teammate_still_sigma, cfg.teammate_still_sigma),
                    )
                )

    def _camera_guess(self, frame: FrameInput, previous: gtsam.Pose3) -> gtsam.Pose3:
        """Initial camera pose: the previous one, or -- max-mixture model, teammate seen before
        and standing still since -- resected from the teammate's estimated pose through the
        candidate whose normal (via the previous camera attitude) is closest to the teammate's
        normal. Without KLT the previous pose is centimetres off, and LM started there can
        settle in the false candidate's basin (camera orbited ~20 deg about the teammate)."""
        obs = frame.teammate
        if (
            self.config.teammate_model != "max_mixture"
            or obs is None
            or self._last_mate is None
            or self._mate_moved
            or frame.teammate_moved
        ):
            return previous
        mate = self._estimate.atPose3(pose_key(TEAMMATE, self._last_mate))
        normals_w = np.einsum("ij,kj->ki", previous.rotation().matrix(), obs.candidates.R[:, :, 2])
        best = int(np.argmax(normals_w @ mate.rotation().matrix()[:, 2]))
        return mate.compose(obs.candidates.poses()[best].inverse())

    def active_components(self, values: gtsam.Values | None = None) -> dict[int, int]:
        """frame -> index of the circle candidate the max-mixture is linearized at, at `values`
        (default: the current estimate)."""
        est = self.session.estimate() if values is None else values
        return {k: mix.active(est) for k, mix in self.mixtures.items()}

    # ---- results ---------------------------------------------------------------------------
    def positions(self) -> np.ndarray:
        """(T,3) camera positions of the current (smoothed) estimate."""
        est = self.session.estimate()
        return np.array(
            [est.atPose3(pose_key(CAMERA_ROBOT, k)).translation() for k in range(self.frame + 1)]
        )

    def landmarks(self) -> tuple[np.ndarray, np.ndarray]:
        """ids (L,) and world points (L,3) of the admitted landmarks (current estimate)."""
        est = self.session.estimate()
        ids = np.array(sorted(self.admitted), dtype=np.int64)
        return ids, np.array([est.atPoint3(landmark_key(j)) for j in ids]).reshape(-1, 3)


@dataclass(frozen=True)
class SfmRun:
    """Result of `run_cooperative_sfm`: causal (T,3) positions (each frame's estimate when it
    arrived), final (T,3) positions (smoothed over all frames), history: at frame k the
    (k+1,3) estimate of frames 0..k, landmark ids/points, the number of factors, skipped
    (non-finite) pixels, and the per-frame latencies [s]; active_causal / active_final (T,):
    the circle candidate the max-mixture was linearized at when the frame arrived / at the
    end (-1: no mixture that frame)."""

    causal_positions: np.ndarray
    final_positions: np.ndarray
    history: tuple[np.ndarray, ...]
    landmark_ids: np.ndarray
    landmark_points: np.ndarray
    n_factors: int
    skipped_pixels: int
    latencies: np.ndarray
    active_causal: np.ndarray
    active_final: np.ndarray


def run_cooperative_sfm(
    frames: list[FrameInput],
    camera: PinholeCamera,
    config: CooperativeSfmConfig = CooperativeSfmConfig(),
) -> SfmRun:
    """Feed every frame through `CooperativeSfm` and collect the estimates."""
    sfm = CooperativeSfm(camera, config)
    for frame in frames:
        sfm.add_frame(frame)
    ids, points = sfm.landmarks()
    causal, final = np.full(len(frames), -1), np.full(len(frames), -1)
    for k, c in sfm.causal_active.items():
        causal[k] = c
    for k, c in sfm.active_components().items():
        final[k] = c
    return SfmRun(
        np.array(sfm.online_positions),
        sfm.positions(),
        tuple(sfm.history),
        ids,
        points,
        int(sfm.session.graph.size()),
        sfm.skipped_pixels,
        sfm.session.latencies(),
        causal,
        final,
    )
