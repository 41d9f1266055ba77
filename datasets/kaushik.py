"""Scenario `kaushik-p3p-error`: seed 004 (004_fa12d1d18dcbd0db.txt) Sec. III, the P3P error
analysis behind its Table 1 (LED triangle of Sec. II-A, RMS error Eq. (4)), runs batched over
tracks of a climbing robot's overhead camera (docs/design_datasets.md, "Seed 004")."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path

from typing import Literal
import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.datasets.feng import (
    look_at,
    noisy_odometry,
    odometry_covariance,
    project_world,
    relative_poses,
)
from graphloc.config import parse_overrides
from graphloc.config_schema import config_dataclass, setting
from graphloc.datasets.camera_track import CameraTrackLog, write_camera_track

SIDE = 0.3048  # LED triangle side [m] (seed 004 Sec. II-A)
FOCALS_MM = (16.0, 26.0, 36.0)
NOISE_VARIANCES = (3.0, 5.0, 10.0)
NOISE_READINGS = ("variance", "std")


def led_triangle() -> np.ndarray:
    """(3,3) P1, P2, P3: equilateral, side 0.3048 m, P1 at the origin, in the z = 0 plane."""
    return np.array([[0.0, 0.0, 0.0], [SIDE, 0.0, 0.0], [SIDE / 2, SIDE * np.sqrt(3.0) / 2, 0.0]])


@config_dataclass
class KaushikConfig:
    focal_mm: float = setting(16.0, gt=0.0)
    noise_variance: float = setting(3.0, ge=0.0)
    runs: int = setting(1000, ge=1, le=1_000_000)
    frames: int = setting(10, ge=2, le=10_000)
    step: float = setting(0.05, gt=0.0)
    speed: float = setting(0.2, gt=0.0)
    amplitude: float = setting(0.1, ge=0.0)
    wavelength: float = setting(0.5, gt=0.0)
    start_radius: float = setting(0.3, ge=0.0)
    offset: float = setting(0.0, ge=0.0)
    noise_reading: Literal[NOISE_READINGS] = "variance"
    height: float = setting(2.5, gt=0.0)
    pixel_pitch_um: float = setting(13.75, gt=0.0)
    width: int = setting(640, ge=1, le=16384)
    height_px: int = setting(480, ge=1, le=16384)
    odometry_noise: float = setting(0.1, ge=0.0)
    odometry_rot_sigma: float = setting(0.005, ge=0.0)
    seed: int = 0

    @property
    def pixel_sigma(self) -> float:
        """Per-coordinate pixel noise std: Table 1's "Gaussian noise with sigma^2 = v" read as a
        variance (sqrt v, the default) or as a standard deviation (v)."""
        v = float(self.noise_variance)
        return float(np.sqrt(v)) if self.noise_reading == "variance" else v

    def camera(self) -> PinholeCamera:
        focal_px = 1e3 * self.focal_mm / self.pixel_pitch_um
        return PinholeCamera(
            focal_px,
            focal_px,
            (self.width - 1) / 2.0,
            (self.height_px - 1) / 2.0,
            self.width,
            self.height_px,
        )


@dataclass(frozen=True)
class KaushikRuns:
    """`runs` tracks of `frames` updates. times (F,); R_wc (N,F,3,3), t_wc (N,F,3) true camera
    poses; leds (3,3); pixels (N,F,3,2) noisy; odometry: N lists of F-1 noisy relative poses
    (gtsam.Pose3)."""

    config: KaushikConfig
    times: np.ndarray
    R_wc: np.ndarray
    t_wc: np.ndarray
    leds: np.ndarray
    pixels: np.ndarray
    odometry: list


def tracks(config: KaushikConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """True camera rotations (N,F,3,3) and centres (N,F,3): sinusoids at `height` over the LED
    plane with a random start and heading, optical axis at the LED centroid."""
    N, F = config.runs, config.frames
    centroid = led_triangle().mean(axis=0)
    r = config.offset + config.start_radius * np.sqrt(rng.uniform(size=N))
    phi = rng.uniform(0.0, 2.0 * np.pi, size=(2, N))
    start = centroid[:2] + np.stack([r * np.cos(phi[0]), r * np.sin(phi[0])], axis=1)
    s = config.step * np.arange(F)
    along = np.stack([np.cos(phi[1]), np.sin(phi[1])], axis=1)  # (N,2)
    across = np.stack([-along[:, 1], along[:, 0]], axis=1)
    lateral = config.amplitude * np.sin(2.0 * np.pi * s / config.wavelength)
    xy = (
        start[:, None, :]
        + s[None, :, None] * along[:, None, :]
        + lateral[None, :, None] * across[:, None, :]
    )
    pos = np.concatenate([xy, np.full((N, F, 1), config.height)], axis=2)
    heading = np.concatenate(
        [np.broadcast_to(along[:, None, :], (N, F, 2)), np.zeros((N, F, 1))], axis=2
    )
    R = look_at(pos.reshape(-1, 3), centroid, heading.reshape(-1, 3).copy()).reshape(N, F, 3, 3)
    return R, pos


def simulate(config: KaushikConfig = KaushikConfig()) -> KaushikRuns:
    """All runs of one (focal, noise) cell, batched over every frame of every run."""
    rng = np.random.default_rng(config.seed)
    N, F = config.runs, config.frames
    leds = led_triangle()
    R, t = tracks(config, rng)
    camera = config.camera()
    uv, visible = project_world(camera, R.reshape(-1, 3, 3), t.reshape(-1, 3), leds)
    if not visible.all():
        raise ValueError(
            f"kaushik-p3p-error: {int((~visible.all(axis=1)).sum())} frames lose an LED "
            f"(focal {config.focal_mm} mm, height {config.height} m)"
        )
    pixels = uv + rng.normal(0.0, config.pixel_sigma, uv.shape)
    odometry = []
    for n in range(N):
        Rrel, trel = relative_poses(R[n], t[n])
        odometry.append(
            noisy_odometry(Rrel, trel, config.odometry_noise, config.odometry_rot_sigma, rng)
        )
    return KaushikRuns(
        config,
        config.step / config.speed * np.arange(F),
        R,
        t,
        leds,
        pixels.reshape(N, F, 3, 2),
        odometry,
    )


class KaushikP3PErrorScenario:
    """`graphloc simulate kaushik-p3p-error`: one track (runs=1) of one cell in the log format."""

    name = "kaushik-p3p-error"
    config_class = KaushikConfig

    @classmethod
    def generate(cls, out_dir, seed: int = 0, **overrides) -> Path:
        config = replace(
            KaushikConfig(runs=1, seed=seed), **parse_overrides(KaushikConfig, overrides)
        )
        run = simulate(replace(config, runs=1))
        cov = [
            odometry_covariance(o, config.odometry_noise, config.odometry_rot_sigma)
            for o in run.odometry[0]
        ]
        log = CameraTrackLog(
            name=cls.name,
            times=run.times,
            R_wc=run.R_wc[0],
            t_wc=run.t_wc[0],
            layout=run.leds,
            pixels=run.pixels[0],
            camera=config.camera(),
            pixel_sigma=config.pixel_sigma,
            odometry=run.odometry[0],
            odometry_cov=cov,
            surface=(np.array([0.0, 0.0, config.height]), np.array([0.0, 0.0, -1.0])),
            meta={"seed_paper": "004_fa12d1d18dcbd0db.txt Sec. III", "config": asdict(config)},
        )
        return write_camera_track(log, out_dir)
