"""`CooperativeSfm`: the frame-by-frame graph builder of seed 003's cooperative motion and
structure (the factors are listed in benchmarks.cooperative_sfm's docstring)."""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.factors.mixture import (
    MaxMixture,
    component_factors,
    max_mixture_factor,
    mixture_weights,
)
from graphloc.factors.range_bearing import landmark_factor_3d
from graphloc.factors.robust import robust_noise
from graphloc.keys import landmark_key, pose_key
from benchmarks.cooperative_sfm.config import (
    CAMERA_ROBOT,
    TEAMMATE,
    WORLD_UP,
    CooperativeSfmConfig,
    check_frame,
    pose_noise,
)
from graphloc.seams import FrameInput
from graphloc.session import Session


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
        check_frame(frame, self._last_time, self.config.teammate_model)
        ids = np.asarray(frame.features.ids)
        pixels = np.asarray(frame.features.pixels, dtype=float)
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
                    pose_noise(self.config.first_pose_sigma, self.config.first_pose_sigma),
                )
            )
            guess = gtsam.Pose3()
        else:
            sig = self.config.motion.sigmas(frame.camera_moved)
            graph.append(
                gtsam.BetweenFactorPose3(
                    pose_key(CAMERA_ROBOT, k - 1), x, gtsam.Pose3(), pose_noise(*sig)
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
                        pose_noise(cfg.teammate_still_sigma, cfg.teammate_still_sigma),
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
