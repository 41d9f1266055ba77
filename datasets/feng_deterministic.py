"""Seed 000 (000_05137a0a9c449be3.txt) Sec. VI-A: the straight-line trials of the climbing
camera (three snapshots) and the ground robots' mutual-bearing triangle, vectorized over trials
(docs/design_datasets.md, "Seed 000")."""

from __future__ import annotations

from dataclasses import dataclass

from typing import Literal
import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.config_schema import config_dataclass, setting
from graphloc.cameras import ParaboloidOmniCamera, PinholeCamera, angular_sigma
from graphloc.datasets.feng import noisy_pixels
from graphloc.datasets.render import render_mutual_pixels
from graphloc.vision.mutual import localize_three


GROUND_BOXES = np.array(
    [
        [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]],
        [[0.0, 2.0, 0.0], [1.0, 3.0, 1.0]],
        [[2.0, 1.0, 0.0], [3.0, 2.0, 1.0]],
    ]
)
CAMERA_BOX = np.array([[1.0, 1.0, 2.0], [2.0, 2.0, 3.0]])
ORIENTATIONS = ("kept", "redrawn")


@config_dataclass
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
    # C's orientation over the three snapshots: "kept" (drawn once, the robot only translates)
    # or "redrawn" (step 2's pitch/tilt/yaw drawn anew for every snapshot); the seed says neither
    orientation: Literal[ORIENTATIONS] = "kept"

    def camera(self) -> PinholeCamera:
        """The climbing robot's camera C (the same model as
        graphloc.datasets.feng.seed000_camera)."""
        return PinholeCamera.from_fov(self.width, self.height, self.fov_rad)


@dataclass(frozen=True)
class StraightLineTrials:
    """T trials of three snapshots. ground (T,3,3): robot positions (world); R_wc (T,3,3) camera
    orientation at the first snapshot; R_snapshots (T,3,3,3) at each snapshot (all R_wc unless
    Seed000Config.orientation is "redrawn"); positions (T,3,3): true camera centre at snapshots
    0,1,2; pixels (T,3,3,2): pixel of robot j in snapshot s at [t, s, j]; K (3,3); redrawn:
    trials discarded because a robot left the image or was behind the camera."""

    ground: np.ndarray
    R_wc: np.ndarray
    positions: np.ndarray
    pixels: np.ndarray
    K: np.ndarray
    redrawn: int
    R_snapshots: np.ndarray


def _rot_xyz(tilt, pitch, yaw):
    """(T,3,3) = Rz(yaw) Ry(pitch) Rx(tilt)."""
    return Rotation.from_euler("xyz", np.stack([tilt, pitch, yaw], axis=-1)).as_matrix()


# camera looking straight down: optical axis (camera z) = world -z, camera x = world x
LOOK_DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])


def simulate_straight_line_trials(
    n: int, seed: int = 0, config: Seed000Config = Seed000Config()
) -> StraightLineTrials:
    """n trials of the seed 000 section VI-A setup (vectorized; invisible trials redrawn)."""
    if n < 1:
        raise ValueError(f"simulate_straight_line_trials: n must be positive, got {n}")
    rng = np.random.default_rng(seed)
    K = config.camera().K
    parts, have, redrawn = [], 0, 0
    while have < n:
        m = int((n - have) * 1.5) + 8
        lo, hi = GROUND_BOXES[:, 0], GROUND_BOXES[:, 1]
        ground = lo + (hi - lo) * rng.uniform(size=(m, 3, 3))
        a = rng.uniform(0.0, config.max_angle_rad, size=(m, 3))
        R_wc = _rot_xyz(a[:, 0], a[:, 1], a[:, 2]) @ LOOK_DOWN
        R_snap = np.repeat(R_wc[:, None], 3, axis=1)
        if config.orientation == "redrawn":
            b = rng.uniform(0.0, config.max_angle_rad, size=(m, 2, 3))
            R_snap[:, 1:] = _rot_xyz(b[..., 0], b[..., 1], b[..., 2]) @ LOOK_DOWN
        start = CAMERA_BOX[0] + (CAMERA_BOX[1] - CAMERA_BOX[0]) * rng.uniform(size=(m, 3))
        tilt, pitch = rng.uniform(0.0, config.max_angle_rad, size=(2, m))
        direction = np.stack(
            [np.cos(tilt) * np.cos(pitch), np.cos(tilt) * np.sin(pitch), np.sin(tilt)], -1
        )
        steps = rng.normal(config.step_mean, config.step_sigma, size=(m, 2))
        while (bad := steps < config.min_step).any():
            steps[bad] = rng.normal(config.step_mean, config.step_sigma, size=int(bad.sum()))
        travel = np.concatenate([np.zeros((m, 1)), np.cumsum(steps, axis=1)], axis=1)  # (m,3)
        positions = start[:, None, :] + travel[..., None] * direction[:, None, :]
        lateral = rng.normal(0.0, config.lateral_sigma, size=(m, 3, 3))
        lateral -= np.einsum("msi,mi->ms", lateral, direction)[..., None] * direction[:, None, :]
        positions = positions + lateral
        # project: X_c = R_wc^T (X - c)
        Xc = np.einsum("msji,msnj->msni", R_snap, ground[:, None, :, :] - positions[:, :, None, :])
        uvw = np.einsum("ij,msnj->msni", K, Xc)
        pix = uvw[..., :2] / uvw[..., 2:3]
        ang = rng.uniform(0.0, 2.0 * np.pi, size=pix.shape[:-1])
        r = rng.normal(0.0, config.pixel_sigma, size=pix.shape[:-1])
        pix = pix + np.stack([r * np.cos(ang), r * np.sin(ang)], -1)
        visible = (
            (Xc[..., 2] > 0)
            & (pix[..., 0] >= 0)
            & (pix[..., 0] < config.width)
            & (pix[..., 1] >= 0)
            & (pix[..., 1] < config.height)
        ).all(axis=(1, 2))
        take = np.nonzero(visible)[0][: n - have]
        redrawn += int((~visible[: take[-1] + 1]).sum()) if take.size else m
        parts.append((ground[take], R_wc[take], positions[take], pix[take], R_snap[take]))
        have += take.size
    ground, R_wc, positions, pix, R_snap = (np.concatenate(p) for p in zip(*parts))
    return StraightLineTrials(
        ground=ground,
        R_wc=R_wc,
        positions=positions,
        pixels=pix,
        K=K,
        redrawn=redrawn,
        R_snapshots=R_snap,
    )


@config_dataclass
class TableIConfig:
    """Seed 000 Sec. VI-A, the Table I scenario. scale: the workspace size that turns errors
    into the paper's "relative error" ("within a relative error of 1e-3 meters out of a scale
    of three meters"); success_tol [m]: also counted: trials whose three estimated positions of
    C are all within this of the truth; omni_max_polar [rad]: field of view of the ground
    robots' paraboloid cameras from the mirror axis; max_redraws: ground-camera orientations
    redrawn while a robot is outside another's field of view (counted); workers: processes of
    the reproduction (benchmarks.seed000); lateral_sigma [m], orientation:
    Seed000Config's (the climbing robot's position noise perpendicular to its motion; its
    orientation kept or redrawn per snapshot), swept by benchmarks.seed_baselines."""

    trials: int = setting(1000, ge=1, le=1_000_000)
    seed: int = 0
    pixel_sigma: float = setting(0.5, ge=0.0)
    omni_size: int = setting(512, ge=8, le=8192)
    omni_max_polar: float = 2.0 * np.pi / 3.0
    scale: float = setting(3.0, ge=0.0)
    success_tol: float = setting(0.1, ge=0.0)
    max_redraws: int = setting(50, ge=0, le=10_000)
    workers: int = setting(2, ge=1, le=256)
    lateral_sigma: float = setting(0.001, ge=0.0)
    orientation: str = "kept"


@dataclass(frozen=True)
class GroundTriangle:
    """Ground robots C1..C3 for T trials. R (T,3,3,3): camera-to-world rotations; estimated
    (T,3,3): positions from mutual bearings (C1 the reference), NaN where the mutual solver
    rejected the formation, status (T,) its status; pixels (T,3,3,2) noisy [observer i, robot
    j], bearings (T,3,3,3) lifted and bearing_sigma (T,3,3) [rad] (diagonal NaN); visible (T,):
    every robot inside the others' field of view; redrawn: orientation redraws."""

    R: np.ndarray
    estimated: np.ndarray
    status: np.ndarray
    pixels: np.ndarray
    bearings: np.ndarray
    bearing_sigma: np.ndarray
    visible: np.ndarray
    redrawn: int


def ground_triangle(
    ground: np.ndarray, config: TableIConfig, rng: np.random.Generator
) -> GroundTriangle:
    """Seed 000 Sec. VI-A steps 1-2 for the ground robots: orientations with pitch, tilt, yaw
    each U(0, pi/6), mutual pixels in 512x512 paraboloid omni images (Sec. II) with N(0, 0.5)
    px noise in a random direction, then the three-robot algorithm (Sec. III-A,
    graphloc.vision.mutual) with |T_12| known; C1's pose is the reference."""
    T = len(ground)
    omni = ParaboloidOmniCamera.from_fov(config.omni_size, config.omni_max_polar)
    off = ~np.eye(3, dtype=bool)
    R = np.empty((T, 3, 3, 3))
    todo = np.arange(T)
    redrawn = 0
    for attempt in range(config.max_redraws + 1):
        angles = rng.uniform(0.0, np.pi / 6, (todo.size * 3, 3))
        R[todo] = Rotation.from_euler("xyz", angles).as_matrix().reshape(-1, 3, 3, 3)
        _, visible = render_mutual_pixels(R[todo], ground[todo], omni)
        todo = todo[~visible[:, off].all(axis=1)]
        if todo.size == 0 or attempt == config.max_redraws:
            break
        redrawn += todo.size
    clean, seen = render_mutual_pixels(R, ground, omni)
    pixels = noisy_pixels(clean, config.pixel_sigma, rng)
    baseline = np.linalg.norm(ground[:, 1] - ground[:, 0], axis=1)
    res = localize_three(pixels, omni, baseline)
    estimated = ground[:, 0, None, :] + np.einsum("nij,nkj->nki", R[:, 0], res.t)
    with np.errstate(invalid="ignore"):
        bearings = omni.pixel_to_bearing(pixels.reshape(-1, 2))[0].reshape(T, 3, 3, 3)
        sigma = angular_sigma(omni, pixels, config.pixel_sigma)
    return GroundTriangle(
        R,
        estimated,
        res.status,
        pixels,
        bearings,
        sigma,
        seen[:, off].all(axis=1),
        redrawn,
    )
