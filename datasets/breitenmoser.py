"""Scenario `breitenmoser-target`: seed 001 (001_0f8f8dae37ce6b79.txt) Sec. V-A experiment 1, a
752x480, 90 deg camera over the large four-marker target at 0.7-3 m, every frame rendered
(`render.render_markers`); the logged pixels are the visible markers' centroids."""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path

import cv2
import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.datasets.feng import look_at
from graphloc.config import parse_overrides
from graphloc.config_schema import config_dataclass, setting
from graphloc.datasets.camera_track import CameraTrackLog, write_camera_track
from graphloc.datasets.render import RenderConfig, render_markers
from graphloc.vision.target import LARGE_TARGET

# centroid noise of the logged marker pixels: rendered centroids at sensor sigma 2 are within
# 0.10 px of the truth (tests/datasets/test_render_markers.py), so 0.1 px, not the optics blur width
CENTROID_SIGMA_PX = 0.1


@config_dataclass
class BreitenmoserConfig:
    """frames: updates; d_min, d_max [m]: camera-target distance ramp (seed 001 V-A: 0.68-1.74 m
    by hand, up to 3 m flown); tilt_deg: viewing direction off vertical; rate_hz."""

    frames: int = setting(50, ge=1, le=10_000, description="camera updates")
    d_min: float = setting(0.7, gt=0.0, description="first camera-target distance [m]")
    d_max: float = setting(3.0, gt=0.0, le=100.0, description="last camera-target distance [m]")
    tilt_deg: float = setting(20.0, ge=0.0, lt=90.0, description="view off vertical [deg]")
    rate_hz: float = setting(10.0, gt=0.0, le=1000.0, description="update rate [Hz]")
    save_images: bool = setting(True, description="write the rendered PNGs")

    def __post_init__(self):
        if not 0.0 < self.d_min <= self.d_max:
            raise ValueError(
                f"BreitenmoserConfig.d_min must be in (0, d_max = {self.d_max:g}], got {self.d_min}"
            )


def seed001_camera() -> PinholeCamera:
    """Seed 001 V-A: Firefly MV, 752x480, 90 deg FOV."""
    return PinholeCamera.from_fov(752, 480, np.pi / 2)


class BreitenmoserTargetScenario:
    name = "breitenmoser-target"
    config_class = BreitenmoserConfig

    @classmethod
    def generate(cls, out_dir, seed: int = 0, **overrides) -> Path:
        config = replace(BreitenmoserConfig(), **parse_overrides(BreitenmoserConfig, overrides))
        rng = np.random.default_rng(seed)
        out = Path(out_dir)
        centre = LARGE_TARGET.points.mean(axis=0)
        n = config.frames
        dist = np.linspace(config.d_min, config.d_max, n)
        azimuth = rng.uniform(0, 2 * np.pi) + np.linspace(0.0, np.pi, n)
        tilt = np.deg2rad(config.tilt_deg)
        eye = centre + dist[:, None] * np.column_stack(
            [
                np.sin(tilt) * np.cos(azimuth),
                np.sin(tilt) * np.sin(azimuth),
                np.full(n, np.cos(tilt)),
            ]
        )
        heading = np.column_stack([-np.sin(azimuth), np.cos(azimuth), np.zeros(n)])
        R = look_at(eye, centre, heading)
        camera = seed001_camera()
        pixels = np.full((n, len(LARGE_TARGET.points), 2), np.nan)
        for k in range(n):
            frame = render_markers(
                camera,
                (LARGE_TARGET.points - eye[k]) @ R[k],
                LARGE_TARGET.marker_diameter / 2,
                RenderConfig(),
                rng,
            )
            pixels[k] = frame.centroids
            if config.save_images:
                (out / "climber" / "images").mkdir(parents=True, exist_ok=True)
                cv2.imwrite(str(out / "climber" / "images" / f"{k:06d}.png"), frame.image)
        times = np.arange(n) / config.rate_hz
        log = CameraTrackLog(
            name=cls.name,
            times=times,
            R_wc=R,
            t_wc=eye,
            layout=LARGE_TARGET.points,
            pixels=pixels,
            camera=camera,
            pixel_sigma=CENTROID_SIGMA_PX,
            odometry=[],
            odometry_cov=[],
            target="target",
            identical_markers=True,
            meta={
                "seed_paper": "001_0f8f8dae37ce6b79.txt Sec. V-A",
                "config": asdict(config),
                "images": "climber/images/%06d.png" if config.save_images else None,
            },
        )
        return write_camera_track(log, out)
