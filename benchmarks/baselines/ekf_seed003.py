"""Seed 003's motion estimator (003_8db27855ce2d5f68.txt, section II-B-2,
eqs. 8-14, and the settings of section III): an Extended Kalman Filter in the
Azarbayejani-Pentland form [1] with the state of eq. 13

    x = [T_x, T_y, T_z beta, w_x, w_y, w_z, beta, X_1, Y_1, Z_1, ..., X_n, Y_n, Z_n]

translation T, incremental rotation w (the vector part of the unit quaternion
dq = (sqrt(1 - eps), w/2), eqs. 11-12), inverse focal length beta, and the world positions of
the n feature points, the first of which is the robot tracker's point (the centre of the
teammate's base). Camera frame coordinates (eq. 13):

    [X_c, Y_c, Z_c beta] = [T_x, T_y, T_z beta] + diag(1, 1, beta) R [X, Y, Z],

image coordinates (eq. 14): u = X_c / (1 + Z_c beta), v = Y_c / (1 + Z_c beta), in metres on the
sensor (pixel offsets times `pixel_pitch`), so 1/beta is the focal length in metres and the
centre of projection is at Z_c = -1/beta. The global rotation R is kept outside the state
and updated after every measurement update with the incremental rotation, which is then reset
to zero ("as described in [1]"); so the filter always linearizes at w = 0.

Dynamics (eq. 8): identity plus noise (the motion is not known a priori). Initial state
(section III): T, w = [0, 0, -1, 0, 0, 0] (camera at the world origin), zero covariance; the
tracker's point from the robot tracker with its covariance ("proper" setting; "ideal": zero,
"noisy": inflated); KLT points "all assumed at the same position": every one on its first ray at
one common depth, with a high variance. Measurement noise (section III): 1 for KLT points,
3 for the robot tracker's point (variances, in pixels^2).

Reading choices where the seed is silent: when a new KLT track starts, its point is added to
the state the same way (common depth along its ray from the current camera estimate); points
whose track is lost are dropped from the state (marginalized); when the teammate has moved
(move-and-stop), the tracker's point is re-initialized at its next sighting from the robot
tracker's new position with the tracker covariance (not used while it is stale); a camera
that knows it stood still gets the `still` process noise.
"""

from __future__ import annotations


from typing import Literal
import gtsam
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from graphloc.cameras import PinholeCamera
from graphloc.seams import FrameInput, MotionNoise
from graphloc.geometry.so3 import skew

TRACKER_SETTINGS = ("proper", "ideal", "noisy")


@config_dataclass
class EkfConfig:
    """pixel_pitch [m/px]: sensor units of eq. 14. beta_rel_sigma: initial std of beta relative
    to 1/f. feature_depth [m], feature_sigma [m]: common initial depth of KLT points (seed III:
    the background starts at 260 cm) and their (high) initial std. klt_variance,
    tracker_variance [px^2]: measurement noise (seed III: 1
    and 3). tracker_setting: initial covariance of the tracker's point -- 'proper' (the
    tracker's covariance), 'ideal' (zero), 'noisy' (x noisy_factor). motion: process noise
    (shared with the graph)."""

    pixel_pitch: float = setting(6e-6, gt=0.0)
    beta_rel_sigma: float = setting(0.01, ge=0.0)
    feature_depth: float = setting(2.6, gt=0.0)
    feature_sigma: float = setting(1.0, gt=0.0)
    klt_variance: float = setting(1.0, gt=0.0)
    tracker_variance: float = setting(3.0, gt=0.0)
    tracker_setting: Literal[TRACKER_SETTINGS] = "proper"
    noisy_factor: float = setting(100.0, gt=0.0)
    motion: MotionNoise = MotionNoise()


N_MOTION = 7  # T (3), w (3), beta
TRACKER_ID = -1  # id of the robot tracker's point among the state's points


def incremental_rotation(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of dq = (sqrt(1 - eps), w_x/2, w_y/2, w_z/2), eps = |w|^2 / 4
    (eqs. 11-12)."""
    eps = float(w @ w) / 4.0
    if eps >= 1.0:
        raise ValueError(f"incremental rotation too large: |w| = {np.sqrt(4 * eps):.3f} >= 2")
    return gtsam.Rot3.Quaternion(np.sqrt(1.0 - eps), *(0.5 * w)).matrix()


class Seed003Ekf:
    """The seed's EKF over `FrameInput`s (the graph's inputs).

    ekf = Seed003Ekf(camera, EkfConfig())
    for frame in frames:
        position = ekf.step(frame)     # camera centre in the world (3,)
    """

    def __init__(self, camera: PinholeCamera, config: EkfConfig = EkfConfig()):
        if camera.dist:
            raise ValueError("Seed003Ekf: the camera must be undistorted (eq. 14 is a pinhole)")
        if abs(camera.fx - camera.fy) > 1e-9 * camera.fx:
            raise ValueError("Seed003Ekf: eq. 14 has one focal length; needs fx == fy")
        self.camera = camera
        self.config = config
        self.x = np.zeros(0)
        self.P = np.zeros((0, 0))
        self.R_global = np.eye(3)  # world -> camera rotation (outside the state, [1])
        self.ids = np.zeros(
            0, np.int64
        )  # point ids in state order (TRACKER_ID for the tracker's point)
        self._last_time = -np.inf
        self.n_frames = 0
        self.positions: list[np.ndarray] = []
        self._tracker_stale = False  # the teammate moved and has not been seen since
        self.skipped_pixels = 0  # non-finite pixels (counted, not used)
        self.skipped_behind = (
            0  # measurements of points the state puts behind the camera (counted, not used)
        )

    # ---- geometry ------------------------------------------------------------------------------
    @property
    def beta(self) -> float:
        return float(self.x[6])

    def camera_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(R_wc (3,3), camera centre in the world (3,)) of the current state."""
        R = incremental_rotation(self.x[3:6]) @ self.R_global
        T_metric = np.array([self.x[0], self.x[1], self.x[2] / self.beta])
        centre = R.T @ (np.array([0.0, 0.0, -1.0 / self.beta]) - T_metric)
        return R.T, centre

    def _sensor(self, pixels: np.ndarray) -> np.ndarray:
        return (pixels - (self.camera.cx, self.camera.cy)) * self.config.pixel_pitch

    def _points_on_rays(self, pixels: np.ndarray, depth: float) -> np.ndarray:
        """World points at camera depth `depth` on the rays of `pixels` (current camera)."""
        R_wc, centre = self.camera_pose()
        xy = (pixels - (self.camera.cx, self.camera.cy)) / self.camera.fx
        pc = np.column_stack([xy * depth, np.full(len(xy), depth)])
        return pc @ R_wc.T + centre

    def _tracker_world(self, obs) -> tuple[np.ndarray, np.ndarray]:
        R_wc, centre = self.camera_pose()
        cov = obs.covariance
        scale = {"proper": 1.0, "ideal": 0.0, "noisy": self.config.noisy_factor}[
            self.config.tracker_setting
        ]
        return R_wc @ obs.centre + centre, scale * (R_wc @ cov @ R_wc.T)

    def _append_points(self, ids: np.ndarray, points: np.ndarray, cov: np.ndarray) -> None:
        """Append points (m,3) with block covariance (3m,3m), uncorrelated with the rest."""
        n = len(self.x)
        self.x = np.concatenate([self.x, points.reshape(-1)])
        P = np.zeros((n + cov.shape[0],) * 2)
        P[:n, :n] = self.P
        P[n:, n:] = cov
        self.P = P
        self.ids = np.concatenate([self.ids, ids.astype(np.int64)])

    def _drop_points(self, keep: np.ndarray) -> None:
        """Keep the points with mask keep (n_points,) (marginalizing a Gaussian = dropping rows)."""
        point_rows = N_MOTION + 3 * np.flatnonzero(keep)[:, None] + np.arange(3)
        idx = np.concatenate([np.arange(N_MOTION), point_rows.ravel()])
        self.x, self.P, self.ids = self.x[idx], self.P[np.ix_(idx, idx)], self.ids[keep]

    # ---- measurement model (eqs. 13-14), vectorized over points -------------------------------
    def _in_front(self, which: np.ndarray) -> np.ndarray:
        """(m,) 1 + Z_c beta > 0 for state points `which` (in front of the centre of projection)."""
        pts = self.x[N_MOTION:].reshape(-1, 3)[which]
        return 1.0 + self.x[2] + self.x[6] * (pts @ self.R_global[2]) > 0

    def predict_measurements(self, which: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """h (2m,) sensor coordinates of state points `which` (m,) and H (2m, n_state)."""
        x = self.x
        R = self.R_global  # linearization at w = 0 (reset after every update)
        pts = x[N_MOTION:].reshape(-1, 3)[which]
        a = pts @ R.T  # R X
        Tx, Ty, Tzb, beta = x[0], x[1], x[2], x[6]
        Xc, Yc = Tx + a[:, 0], Ty + a[:, 1]
        D = 1.0 + Tzb + beta * a[:, 2]
        if (D <= 0).any():
            raise ValueError("Seed003Ekf: a point is behind the camera (1 + Z_c beta <= 0)")
        m = len(which)
        H = np.zeros((2 * m, len(x)))
        dadw = -skew(a)  # d(R(dq) a)/dw at w = 0 is [w]x a = -[a]x w
        rows_u, rows_v = 2 * np.arange(m), 2 * np.arange(m) + 1
        for rows, C, k in ((rows_u, Xc, 0), (rows_v, Yc, 1)):
            H[rows, k] = 1.0 / D
            H[rows, 2] = -C / D**2
            H[rows, 3:6] = dadw[:, k, :] / D[:, None] - (C * beta / D**2)[:, None] * dadw[:, 2, :]
            H[rows, 6] = -C * a[:, 2] / D**2
            cols = N_MOTION + 3 * which[:, None] + np.arange(3)
            H[rows[:, None], cols] = (
                R[k][None, :] / D[:, None] - (C * beta / D**2)[:, None] * R[2][None, :]
            )
        h = np.column_stack([Xc / D, Yc / D]).reshape(-1)
        return h, H

    # ---- one frame -----------------------------------------------------------------------------
    def step(self, frame: FrameInput) -> np.ndarray:
        """Predict, (re)initialize points, update with this frame's pixels; returns the camera
        centre in the world (3,)."""
        if not isinstance(frame, FrameInput):
            raise ValueError(f"Seed003Ekf.step: expected FrameInput, got {type(frame).__name__}")
        if not frame.time > self._last_time:
            raise ValueError(
                f"Seed003Ekf.step: time {frame.time} does not follow {self._last_time}"
            )
        cfg = self.config
        ids = np.asarray(frame.features.ids, dtype=np.int64)
        pixels = np.asarray(frame.features.pixels, dtype=float)
        if ids.ndim != 1 or pixels.shape != (len(ids), 2):
            raise ValueError(
                f"Seed003Ekf.step: frame {frame.time}: ids {ids.shape} / pixels {pixels.shape}"
            )
        self._last_time = frame.time
        finite = np.isfinite(pixels).all(axis=1)
        self.skipped_pixels += int((~finite).sum())
        ids, pixels = ids[finite], pixels[finite]
        if self.n_frames == 0:
            if frame.teammate is None:
                raise ValueError(
                    "Seed003Ekf: the first frame must see the teammate (the tracker's point "
                    "initializes the scale, seed III)"
                )
            beta0 = 1.0 / (self.camera.fx * cfg.pixel_pitch)
            self.x = np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0, beta0])
            self.P = np.zeros((N_MOTION, N_MOTION))
            self.P[6, 6] = (cfg.beta_rel_sigma * beta0) ** 2
            point, cov = self._tracker_world(frame.teammate)
            self._append_points(np.array([TRACKER_ID]), point[None], cov)
        else:
            rot, trans = cfg.motion.sigmas(frame.camera_moved)
            self.P[0:2, 0:2] += np.eye(2) * trans**2
            self.P[2, 2] += (trans * self.beta) ** 2
            self.P[3:6, 3:6] += np.eye(3) * rot**2
            self._tracker_stale |= frame.teammate_moved
            if (
                self._tracker_stale and frame.teammate is not None
            ):  # the tracker's point moved: re-initialize
                self._drop_points(self.ids != TRACKER_ID)
                point, cov = self._tracker_world(frame.teammate)
                self._append_points(np.array([TRACKER_ID]), point[None], cov)
                self._tracker_stale = False
        # KLT points: drop lost ones, add new ones at the common depth
        klt_in_state = self.ids != TRACKER_ID
        keep = ~klt_in_state | np.isin(self.ids, ids)
        if not keep.all():
            self._drop_points(keep)
        new = ~np.isin(ids, self.ids)
        if new.any():
            pts = self._points_on_rays(pixels[new], cfg.feature_depth)
            self._append_points(ids[new], pts, np.eye(3 * int(new.sum())) * cfg.feature_sigma**2)
        # measurement update
        order = {int(i): k for k, i in enumerate(self.ids)}
        which = [order[int(i)] for i in ids]
        z = [self._sensor(pixels)]
        var = [np.full(2 * len(ids), cfg.klt_variance)]
        if (
            frame.teammate is not None
            and np.isfinite(frame.teammate.pixel).all()
            and not self._tracker_stale
        ):
            which.append(order[TRACKER_ID])
            z.append(self._sensor(frame.teammate.pixel[None]))
            var.append(np.full(2, cfg.tracker_variance))
        if which:
            which, z, var = (
                np.array(which),
                np.concatenate(z).reshape(-1, 2),
                np.concatenate(var).reshape(-1, 2),
            )
            front = self._in_front(which)
            self.skipped_behind += int((~front).sum())
            if front.any():
                self._update(
                    which[front], z[front].reshape(-1), var[front].reshape(-1) * cfg.pixel_pitch**2
                )
        self.n_frames += 1
        position = self.camera_pose()[1]
        self.positions.append(position)
        return position

    def _update(self, which: np.ndarray, z: np.ndarray, variances: np.ndarray) -> None:
        """EKF measurement update (eq. 10, Joseph form), then fold w into the global rotation."""
        h, H = self.predict_measurements(which)
        S = H @ self.P @ H.T + np.diag(variances)
        K = np.linalg.solve(S, H @ self.P).T
        self.x = self.x + K @ (z - h)
        IKH = np.eye(len(self.x)) - K @ H
        self.P = IKH @ self.P @ IKH.T + K @ np.diag(variances) @ K.T
        self.P = 0.5 * (self.P + self.P.T)
        w = self.x[3:6].copy()
        # fold the incremental rotation: R = R(dq) R_global, T and points unchanged ([1])
        self.R_global = incremental_rotation(w) @ self.R_global
        self.x[3:6] = 0.0

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """ids (n,) and world positions (n,3) of the KLT points in the state."""
        mask = self.ids != TRACKER_ID
        return self.ids[mask], self.x[N_MOTION:].reshape(-1, 3)[mask]


def run_ekf(
    frames: list[FrameInput], camera: PinholeCamera, config: EkfConfig = EkfConfig()
) -> np.ndarray:
    """(T,3) camera centres of the EKF over `frames` (causal, as the filter runs)."""
    ekf = Seed003Ekf(camera, config)
    for frame in frames:
        ekf.step(frame)
    return np.array(ekf.positions)
