"""Seed 000 (000_05137a0a9c449be3.txt) section VI-A, the deterministic-algorithm simulation:
three ground robots uniform in the sub-cubes (0,0,0)-(1,1,1), (0,2,0)-(1,3,1), (2,1,0)-(3,2,1);
a climbing-robot camera C uniform in (1,1,2)-(2,2,3) under the ceiling, looking down with
pitch/tilt/yaw each U(0, pi/6); C moves twice by X ~ N(0.4, 0.2) m along a direction with tilt
and pitch U(0, pi/6) (steps 3-4), each position perturbed by N(0, 0.001) m perpendicular to the
motion; a 640x480 pinhole with a 2pi/3 horizontal field of view sees the three robots with pixel
noise of N(0, 0.5) px in a uniformly random direction.

Interpretation where the seed is silent: the camera keeps its orientation while moving; the
motion direction is (cos(tilt) cos(pitch), cos(tilt) sin(pitch), sin(tilt)) in the world frame
(tilt = elevation, pitch = heading); step lengths below 0.05 m are redrawn; trials where a robot
leaves the image are redrawn and counted. The ground robots' positions are known exactly.
The same trials serve the baseline and the engines, so comparisons run identical inputs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.cameras import PinholeCamera


GROUND_BOXES = np.array([[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]],
                         [[0.0, 2.0, 0.0], [1.0, 3.0, 1.0]],
                         [[2.0, 1.0, 0.0], [3.0, 2.0, 1.0]]])
CAMERA_BOX = np.array([[1.0, 1.0, 2.0], [2.0, 2.0, 3.0]])


@dataclass(frozen=True)
class Seed000Config:
    width: int = 640
    height: int = 480
    fov_rad: float = 2.0 * np.pi / 3.0  # horizontal
    pixel_sigma: float = 0.5
    max_angle_rad: float = np.pi / 6.0  # orientation and motion-direction angles U(0, this)
    step_mean: float = 0.4
    step_sigma: float = 0.2
    min_step: float = 0.05
    lateral_sigma: float = 0.001  # position noise perpendicular to the motion [m]

    def camera(self) -> PinholeCamera:
        """The climbing robot's camera C (the same model as graphloc.datasets.feng.seed000_camera)."""
        return PinholeCamera.from_fov(self.width, self.height, self.fov_rad)

    def camera_matrix(self) -> np.ndarray:
        return self.camera().K


@dataclass(frozen=True)
class StraightLineTrials:
    """T trials of three snapshots. ground (T,3,3): robot positions (world); R_wc (T,3,3) camera
    orientation (fixed over the snapshots); positions (T,3,3): true camera centre at snapshots
    0,1,2; pixels (T,3,3,2): pixel of robot j in snapshot s at [t, s, j]; K (3,3); redrawn:
    trials discarded because a robot left the image or was behind the camera."""

    ground: np.ndarray
    R_wc: np.ndarray
    positions: np.ndarray
    pixels: np.ndarray
    K: np.ndarray
    redrawn: int


def _rot_xyz(tilt, pitch, yaw):
    """(T,3,3) = Rz(yaw) Ry(pitch) Rx(tilt)."""
    return Rotation.from_euler("xyz", np.stack([tilt, pitch, yaw], axis=-1)).as_matrix()


# camera looking straight down: optical axis (camera z) = world -z, camera x = world x
LOOK_DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])


def simulate_straight_line_trials(n: int, seed: int = 0, config: Seed000Config = Seed000Config()) -> StraightLineTrials:
    """n trials of the seed 000 section VI-A setup (vectorized; invisible trials redrawn)."""
    if n < 1:
        raise ValueError(f"simulate_straight_line_trials: n must be positive, got {n}")
    rng = np.random.default_rng(seed)
    K = config.camera_matrix()
    parts, have, redrawn = [], 0, 0
    while have < n:
        m = int((n - have) * 1.5) + 8
        lo, hi = GROUND_BOXES[:, 0], GROUND_BOXES[:, 1]
        ground = lo + (hi - lo) * rng.uniform(size=(m, 3, 3))
        a = rng.uniform(0.0, config.max_angle_rad, size=(m, 3))
        R_wc = _rot_xyz(a[:, 0], a[:, 1], a[:, 2]) @ LOOK_DOWN
        start = CAMERA_BOX[0] + (CAMERA_BOX[1] - CAMERA_BOX[0]) * rng.uniform(size=(m, 3))
        tilt, pitch = rng.uniform(0.0, config.max_angle_rad, size=(2, m))
        direction = np.stack([np.cos(tilt) * np.cos(pitch), np.cos(tilt) * np.sin(pitch), np.sin(tilt)], -1)
        steps = rng.normal(config.step_mean, config.step_sigma, size=(m, 2))
        while (bad := steps < config.min_step).any():
            steps[bad] = rng.normal(config.step_mean, config.step_sigma, size=int(bad.sum()))
        travel = np.concatenate([np.zeros((m, 1)), np.cumsum(steps, axis=1)], axis=1)  # (m,3)
        positions = start[:, None, :] + travel[..., None] * direction[:, None, :]
        lateral = rng.normal(0.0, config.lateral_sigma, size=(m, 3, 3))
        lateral -= np.einsum("msi,mi->ms", lateral, direction)[..., None] * direction[:, None, :]
        positions = positions + lateral
        # project: X_c = R_wc^T (X - c)
        Xc = np.einsum("mji,msnj->msni", R_wc, ground[:, None, :, :] - positions[:, :, None, :])
        uvw = np.einsum("ij,msnj->msni", K, Xc)
        pix = uvw[..., :2] / uvw[..., 2:3]
        ang = rng.uniform(0.0, 2.0 * np.pi, size=pix.shape[:-1])
        r = rng.normal(0.0, config.pixel_sigma, size=pix.shape[:-1])
        pix = pix + np.stack([r * np.cos(ang), r * np.sin(ang)], -1)
        visible = ((Xc[..., 2] > 0) & (pix[..., 0] >= 0) & (pix[..., 0] < config.width)
                   & (pix[..., 1] >= 0) & (pix[..., 1] < config.height)).all(axis=(1, 2))
        take = np.nonzero(visible)[0][: n - have]
        redrawn += int((~visible[: take[-1] + 1]).sum()) if take.size else m
        parts.append((ground[take], R_wc[take], positions[take], pix[take]))
        have += take.size
    ground, R_wc, positions, pix = (np.concatenate(p) for p in zip(*parts))
    return StraightLineTrials(ground=ground, R_wc=R_wc, positions=positions, pixels=pix, K=K, redrawn=redrawn)
