"""Scenario `crawler-pair`: seed 003 (003_8db27855ce2d5f68.txt) Sec. II-III, two small crawlers
that move and stop in turns, the moving robot's camera rendering the textured scene and the
teammate's 3.8 cm base (docs/design_datasets.md, "crawler-pair")."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from functools import cached_property

from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from graphloc.cameras import PinholeCamera
from graphloc.config import parse_overrides
from graphloc.config_schema import config_dataclass, setting
from graphloc.datasets.crawler_pair_log import write_crawler_pair_log
from graphloc.datasets.textured_scene import TexturedScene, disk_coverage, make_texture
from graphloc.vision.features import FeatureConfig
from graphloc.vision.teammate import TeammateConfig, measure_frames

MOVERS = ("camera", "teammate")


def default_schedule() -> tuple[str, ...]:
    """Move-and-stop (seed 003 II): camera 8 steps, teammate 3 steps, camera 4 steps."""
    return ("camera",) * 8 + ("teammate",) * 3 + ("camera",) * 4


@config_dataclass
class CrawlerPairConfig:
    """Geometry [m], motion per step, rendering and noise. schedule: who moves between frames
    t and t+1 (len = n_frames - 1). pixel_pitch [m/px]: sensor pitch (the seed's image-plane
    units in eq. 14). base_colour: BGR of the base (the colour signature of II-A-1)."""

    width: int = setting(640, ge=1, le=8192)
    height: int = setting(480, ge=1, le=8192)
    hfov_deg: float = setting(50.0, gt=0.0)
    pixel_pitch: float = setting(6e-6, gt=0.0)
    base_diameter: float = setting(0.038, gt=0.0)
    start_distance: float = setting(0.83, gt=0.0)
    teammate_lateral: float = 0.03
    teammate_heading_deg: float = 12.0
    background_distance: float = setting(2.6, gt=0.0)
    camera_height: float = setting(0.05, gt=0.0)
    schedule: tuple[str, ...] = field(default_factory=default_schedule)
    camera_step: float = setting(0.012, ge=0.0)
    camera_lateral_std: float = setting(0.003, ge=0.0)
    camera_yaw_std_deg: float = setting(0.8, ge=0.0)
    roughness_deg: float = setting(1.0, ge=0.0)
    bounce_std: float = setting(0.001, ge=0.0)
    teammate_step: float = setting(0.02, ge=0.0)
    teammate_heading_std_deg: float = setting(0.5, ge=0.0)
    teammate_odometry_rel_std: float = setting(0.02, ge=0.0)
    base_colour: tuple[float, float, float] = (40.0, 40.0, 200.0)
    texel: float = setting(0.002, gt=0.0)
    supersample: int = setting(2, ge=1, le=8)
    blur_sigma: float = setting(0.6, ge=0.0)
    noise_sigma: float = setting(2.0, ge=0.0)
    # N of seed III: KLT tracks + the robot tracker's point (log writer)
    n_features: int = setting(10, ge=1, le=10_000)
    seed: int = 0

    def __post_init__(self):
        if not self.background_distance > self.start_distance + 0.5:
            raise ValueError(
                "CrawlerPairConfig.background_distance must exceed start_distance + 0.5 m, "
                f"got {self.background_distance!r}"
            )
        if not self.camera_height > self.base_diameter / 2:
            raise ValueError(
                "CrawlerPairConfig.camera_height must exceed the base radius "
                f"{self.base_diameter / 2:g}, got {self.camera_height!r}"
            )
        bad = [i for i, m in enumerate(self.schedule) if m not in MOVERS]
        if bad:
            raise ValueError(
                f"CrawlerPairConfig.schedule[{bad[0]}] must be one of {MOVERS}, "
                f"got {self.schedule[bad[0]]!r}"
            )

    @property
    def n_frames(self) -> int:
        return len(self.schedule) + 1

    @property
    def base_radius(self) -> float:
        return 0.5 * self.base_diameter

    def camera(self) -> PinholeCamera:
        return PinholeCamera.from_fov(self.width, self.height, np.radians(self.hfov_deg))


@dataclass(frozen=True)
class CrawlerPairSequence:
    """A rendered run (T frames).

    images (T,H,W,3) uint8 BGR; R_wc (T,3,3), t_wc (T,3): the moving robot's camera in the
    world; base_centre (T,3), base_normal (T,3): the teammate's base disk in the world (normal
    towards the back, i.e. towards the camera side); mover (T-1,) who moved between t and t+1;
    teammate_odometry (T-1,) measured distance the teammate travelled (0 when it stood still),
    teammate_odometry_std (T-1,) its std. camera, config: what rendered it."""

    images: np.ndarray
    R_wc: np.ndarray
    t_wc: np.ndarray
    base_centre: np.ndarray
    base_normal: np.ndarray
    mover: tuple[str, ...]
    teammate_odometry: np.ndarray
    teammate_odometry_std: np.ndarray
    camera: PinholeCamera
    config: CrawlerPairConfig
    scene: TexturedScene

    def __len__(self) -> int:
        return len(self.images)

    def frame_flags(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per frame (T,): camera_moved, teammate_moved (since the previous frame; False at 0),
        teammate odometry distance and its std (0 where it stood still)."""
        mover = np.array(("",) + self.mover)
        odometry, std = np.r_[0.0, self.teammate_odometry], np.r_[0.0, self.teammate_odometry_std]
        return mover == "camera", mover == "teammate", odometry, std

    def base_in_camera(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        """Base centre (3,) and normal (3,) in camera t's frame."""
        R = self.R_wc[t]
        return R.T @ (self.base_centre[t] - self.t_wc[t]), R.T @ self.base_normal[t]


def _rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


class CrawlerPairScenario:
    """Renders `CrawlerPairSequence`s: `CrawlerPairScenario(config).render_sequence()`;
    `generate` writes one as a log (`graphloc simulate crawler-pair`)."""

    name = "crawler-pair"
    config_class = CrawlerPairConfig

    def __init__(self, config: CrawlerPairConfig = CrawlerPairConfig()):
        self.config = config

    @cached_property
    def scene(self) -> TexturedScene:
        cfg = self.config
        rng = np.random.default_rng([cfg.seed, 7])
        # the field of view plus the robot's turns
        half_w = cfg.background_distance * np.tan(np.radians(cfg.hfov_deg) / 2) + 0.6
        wall_h = 0.6 * half_w + cfg.camera_height
        wall = make_texture(
            rng, int(wall_h / cfg.texel), int(2 * half_w / cfg.texel), (0.95, 1.0, 0.9)
        )
        ground_len = cfg.background_distance + 0.6
        ground = make_texture(
            rng, int(ground_len / cfg.texel), int(2 * half_w / cfg.texel), (0.8, 1.0, 0.85)
        )
        return TexturedScene(
            cfg.background_distance,
            cfg.camera_height,
            cfg.texel,
            wall,
            (-half_w, cfg.camera_height - wall_h),
            ground,
            (-half_w, -0.5),
        )

    def trajectories(self, rng: np.random.Generator):
        """Camera R_wc (T,3,3), t_wc (T,3); base centre (T,3), normal (T,3); teammate
        odometry (T-1,) and its std (T-1,)."""
        cfg = self.config
        T = cfg.n_frames
        yaw = np.zeros(T)
        pos = np.zeros((T, 3))
        heading = np.radians(cfg.teammate_heading_deg)
        centre = np.zeros((T, 3))
        normal = np.zeros((T, 3))
        centre[0] = (cfg.teammate_lateral, cfg.camera_height - cfg.base_radius, cfg.start_distance)
        theta = np.full(T, heading)  # teammate heading: its forward axis is R_y(theta) z
        odo = np.zeros(T - 1)
        odo_std = np.zeros(T - 1)
        for t, who in enumerate(cfg.schedule):
            yaw[t + 1], theta[t + 1] = yaw[t], theta[t]
            pos[t + 1], centre[t + 1] = pos[t], centre[t]
            if who == "camera":
                yaw[t + 1] = yaw[t] + np.radians(cfg.camera_yaw_std_deg) * rng.normal()
                fwd = np.array([np.sin(yaw[t]), 0.0, np.cos(yaw[t])])
                side = np.array([np.cos(yaw[t]), 0.0, -np.sin(yaw[t])])
                pos[t + 1] = (
                    pos[t] + cfg.camera_step * fwd + cfg.camera_lateral_std * rng.normal() * side
                )
                pos[t + 1, 1] = cfg.bounce_std * rng.normal()
            else:
                theta[t + 1] = theta[t] + np.radians(cfg.teammate_heading_std_deg) * rng.normal()
                step = cfg.teammate_step * (1.0 + 0.1 * rng.normal())
                mid = 0.5 * (theta[t] + theta[t + 1])
                centre[t + 1] = centre[t] + step * np.array([np.sin(mid), 0.0, np.cos(mid)])
                odo_std[t] = max(cfg.teammate_odometry_rel_std * step, 1e-4)
                odo[t] = step + odo_std[t] * rng.normal()
        # the back face: towards -forward
        normal[:] = -np.stack([np.sin(theta), np.zeros(T), np.cos(theta)], axis=1)
        pitch = np.radians(cfg.roughness_deg) * rng.normal(size=T)
        roll = np.radians(cfg.roughness_deg) * rng.normal(size=T)
        pitch[0] = roll[0] = 0.0  # the world frame is camera 0
        stays = np.array([False] + [m == "teammate" for m in cfg.schedule])
        for t in range(1, T):  # a robot that did not move keeps its attitude
            if stays[t]:
                pitch[t], roll[t] = pitch[t - 1], roll[t - 1]
        R = np.stack([_rot_y(a) @ _rot_x(p) @ _rot_z(r) for a, p, r in zip(yaw, pitch, roll)])
        return R, pos, centre, normal, odo, odo_std

    def render(
        self,
        R_wc: np.ndarray,
        t_wc: np.ndarray,
        centre_w: np.ndarray,
        normal_w: np.ndarray,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """One BGR frame (H,W,3) uint8 of the scene and the base disk seen from (R_wc, t_wc)."""
        cfg = self.config
        img = self.background(R_wc, t_wc)
        coverage = disk_coverage(
            cfg.camera(), R_wc.T @ (centre_w - t_wc), R_wc.T @ normal_w, cfg.base_radius
        )
        img = img * (1.0 - coverage[..., None]) + np.float32(cfg.base_colour) * coverage[..., None]
        if cfg.blur_sigma > 0:
            img = cv2.GaussianBlur(img, (0, 0), cfg.blur_sigma)
        if cfg.noise_sigma > 0:
            img = img + rng.normal(0.0, cfg.noise_sigma, img.shape).astype(np.float32)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)

    def background(self, R_wc: np.ndarray, t_wc: np.ndarray) -> np.ndarray:
        """(H,W,3) float32 BGR of the textured wall and ground seen from (R_wc, t_wc), before the
        base disk, blur and sensor noise."""
        return self.scene.image(self.config.camera(), self.config.supersample, R_wc, t_wc)

    @classmethod
    def generate(cls, out_dir, seed: int = 0, **overrides) -> Path:
        """Render a sequence, run seed 003's front-end on it (n_features - 1 KLT tracks plus
        the teammate's base, as the seed counts N), write the measurements; the manifest path."""
        config = replace(
            CrawlerPairConfig(seed=seed), **parse_overrides(CrawlerPairConfig, overrides)
        )
        seq = cls(config).render_sequence()
        camera_moved, teammate_moved, odo, odo_std = seq.frame_flags()
        frames, report = measure_frames(
            seq.images,
            seq.camera,
            camera_moved,
            teammate_moved,
            odo,
            odo_std,
            FeatureConfig(max_features=config.n_features - 1),
            TeammateConfig(radius=config.base_radius),
        )
        meta = {
            "seed_paper": "003_8db27855ce2d5f68.txt Sec. III",
            "config": asdict(config),
            "front_end": asdict(report),
        }
        return write_crawler_pair_log(seq, frames, out_dir, meta=meta)

    def render_sequence(self, progress: bool = False) -> CrawlerPairSequence:
        cfg = self.config
        rng = np.random.default_rng(cfg.seed)
        R, t, centre, normal, odo, odo_std = self.trajectories(rng)
        frames = range(cfg.n_frames)
        if progress:
            frames = tqdm(frames, desc=f"render crawler-pair seed {cfg.seed}", leave=False)
        images = np.stack([self.render(R[k], t[k], centre[k], normal[k], rng) for k in frames])
        return CrawlerPairSequence(
            images,
            R,
            t,
            centre,
            normal,
            tuple(cfg.schedule),
            odo,
            odo_std,
            cfg.camera(),
            cfg,
            self.scene,
        )
