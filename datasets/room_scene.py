"""The `dual-robot-room` scene: four room variants, the ground robot's LED triangle and the
sensors, ray cast with Open3D (seed 004 Sec. II-A, Fig. 1; Sec. IV-A: LiDAR noise, dropouts and
spurious returns)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from graphloc.cameras import PinholeCamera
from graphloc.config_schema import config_dataclass, setting
from graphloc.datasets.camera_track import stack_poses

VARIANTS = ("furnished", "empty", "rectangular", "low_overlap")
LED_SIDE = 0.3048  # seed 004 Sec. II.A


@config_dataclass
class LidarConfig:
    """Spinning 3D LiDAR: `beams` elevations in [elev_min, elev_max] deg, `azimuths` per turn."""

    beams: int = setting(48, ge=1, le=1024)
    azimuths: int = setting(450, ge=1, le=10_000)
    elev_min_deg: float = setting(-25.0, ge=-90.0)
    elev_max_deg: float = setting(50.0, ge=-90.0, le=90.0)
    min_range: float = setting(0.19, ge=0.0)  # seed 004 Sec. IV.A: 0.19 m .. 4 m
    max_range: float = setting(8.0, gt=0.0, le=1000.0)
    range_noise: float = setting(0.005, ge=0.0)  # [m] 1-sigma along the ray
    dropout: float = setting(0.05, ge=0.0, lt=1.0)  # probability a return is missing
    # probability a return is replaced by a random shorter range
    spurious: float = setting(0.005, ge=0.0, le=1.0)

    def __post_init__(self):
        if not -90.0 <= self.elev_min_deg <= self.elev_max_deg:
            raise ValueError(
                f"LidarConfig.elev_min_deg must be in [-90, elev_max_deg = {self.elev_max_deg:g}], "
                f"got {self.elev_min_deg}"
            )
        if not 0.0 <= self.min_range < self.max_range:
            raise ValueError(
                f"LidarConfig.min_range must be in [0, max_range = {self.max_range:g}), "
                f"got {self.min_range}"
            )


@config_dataclass
class CameraConfig:
    """Downward pinhole camera of the ceiling robot (no distortion)."""

    width: int = setting(640, ge=1, le=16384)
    height: int = setting(480, ge=1, le=16384)
    fx: float = setting(500.0, gt=0.0)
    fy: float = setting(500.0, gt=0.0)
    cx: float = 320.0
    cy: float = 240.0
    pixel_noise: float = setting(0.3, ge=0.0)  # [px] 1-sigma

    def pinhole(self) -> PinholeCamera:
        return PinholeCamera(self.fx, self.fy, self.cx, self.cy, self.width, self.height)


def rot_z(yaw: np.ndarray) -> np.ndarray:
    """(N,) yaw -> (N,3,3)."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.zeros(np.shape(yaw) + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


FLIP_X = np.diag([1.0, -1.0, -1.0])  # 180 deg about x: the ceiling robot is upside down


def led_positions() -> np.ndarray:
    """(3,3) LED centres P1..P3 in the ground LiDAR frame: equilateral, side 0.3048 m
    (seed 004 Fig. 1B), on a plate 0.12 m above the LiDAR centre."""
    r = LED_SIDE / np.sqrt(3.0)
    ang = np.deg2rad([0.0, 120.0, 240.0])
    return np.stack([r * np.cos(ang), r * np.sin(ang), np.full(3, 0.12)], axis=1)


# the camera in the ceiling-LiDAR frame (axes parallel)
T_CEILING_CAMERA = stack_poses(np.eye(3)[None], np.array([[0.10, 0.0, 0.04]]))[0]


@dataclass(frozen=True)
class Box:
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]


@dataclass(frozen=True)
class Room:
    size: tuple[float, float, float]  # x, y, height; floor at z = 0, corner at origin
    furniture: tuple[Box, ...]

    def mesh(self) -> o3d.geometry.TriangleMesh:
        mesh = _box_mesh(Box((0.0, 0.0, 0.0), self.size))
        for box in self.furniture:
            mesh += _box_mesh(box)
        return mesh

    def free(self, xy: np.ndarray, margin: float) -> np.ndarray:
        """(N,2) -> (N,) True where a disc of radius `margin` touches no wall or furniture
        footprint."""
        xy = np.atleast_2d(xy)
        ok = (xy[:, 0] > margin) & (xy[:, 0] < self.size[0] - margin)
        ok &= (xy[:, 1] > margin) & (xy[:, 1] < self.size[1] - margin)
        for b in self.furniture:
            inside = (xy[:, 0] > b.lo[0] - margin) & (xy[:, 0] < b.hi[0] + margin)
            inside &= (xy[:, 1] > b.lo[1] - margin) & (xy[:, 1] < b.hi[1] + margin)
            ok &= ~inside
        return ok


def _box_mesh(box: Box) -> o3d.geometry.TriangleMesh:
    lo, hi = np.asarray(box.lo), np.asarray(box.hi)
    m = o3d.geometry.TriangleMesh.create_box(*(hi - lo))
    return m.translate(lo)


def _table(x, y, w, d, h=0.75, top=0.04, leg=0.05) -> tuple[Box, ...]:
    parts = [Box((x, y, h - top), (x + w, y + d, h))]
    for lx, ly in ((x, y), (x + w - leg, y), (x, y + d - leg), (x + w - leg, y + d - leg)):
        parts.append(Box((lx, ly, 0.0), (lx + leg, ly + leg, h - top)))
    return tuple(parts)


def make_room(variant: str) -> Room:
    """The four variants of the issue: furnished, nearly empty, rectangular (symmetric up to a
    180 deg yaw), low overlap (long room with tall shelving, short LiDAR range)."""
    if variant == "furnished":
        furniture = (
            *_table(1.0, 0.6, 1.4, 0.8),
            *_table(4.6, 3.2, 1.2, 1.2, h=0.72),
            Box((6.3, 0.3, 0.0), (6.9, 1.5, 1.1)),  # cabinet
            Box((0.2, 3.9, 0.0), (2.2, 4.3, 1.8)),  # bookshelf
            Box((3.2, 4.2, 0.0), (3.7, 4.7, 0.5)),  # crate
        )
        return Room((7.0, 5.0, 3.0), furniture)
    if variant == "empty":
        return Room((6.0, 4.5, 2.8), (Box((5.4, 3.9, 0.0), (5.8, 4.3, 0.4)),))
    if variant == "rectangular":
        return Room((6.0, 4.0, 2.8), ())
    if variant == "low_overlap":
        furniture = (
            Box((2.5, 1.5, 0.0), (2.9, 4.5, 1.9)),  # shelving rows
            Box((6.0, 0.0, 0.0), (6.4, 3.0, 1.9)),
            Box((9.0, 2.8, 0.0), (9.4, 6.0, 1.9)),
            *_table(4.0, 4.3, 1.2, 0.8),
        )
        return Room((12.0, 6.0, 3.0), furniture)
    raise ValueError(f"unknown dual-robot-room variant {variant!r}; one of {VARIANTS}")


def lidar_directions(cfg: LidarConfig, phase: np.ndarray) -> np.ndarray:
    """(F, beams*azimuths, 3) unit ray directions in the LiDAR frame; `phase` (F,) [rad] is each
    frame's random firing offset in azimuth (a spinning LiDAR is not synchronised to its frames)."""
    el = np.deg2rad(np.linspace(cfg.elev_min_deg, cfg.elev_max_deg, cfg.beams))
    az = np.linspace(0.0, 2 * np.pi, cfg.azimuths, endpoint=False)
    E, A = np.meshgrid(el, az, indexing="ij")
    E, A = E.reshape(1, -1), A.reshape(1, -1) + np.asarray(phase).reshape(-1, 1)
    E = np.broadcast_to(E, A.shape)
    return np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=-1)


def raycast(scene, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    rays = np.concatenate([origins, dirs], axis=-1).astype(np.float32)
    return scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(float)


def scan_frames(scene, poses: np.ndarray, cfg: LidarConfig, rng: np.random.Generator):
    """Ray cast all (F,4,4) LiDAR poses at once; returns list of (N_f,3) points in the sensor
    frame and counts {rays, no_return, dropout, spurious}."""
    F = len(poses)
    d = lidar_directions(cfg, rng.uniform(0.0, 2 * np.pi / cfg.azimuths, F))
    N = d.shape[1]
    dirs_w = np.einsum("fij,fnj->fni", poses[:, :3, :3], d)
    origins = np.broadcast_to(poses[:, None, :3, 3], (F, N, 3))
    r = raycast(scene, origins.reshape(-1, 3), dirs_w.reshape(-1, 3)).reshape(F, N)
    hit = np.isfinite(r) & (r >= cfg.min_range) & (r <= cfg.max_range)
    r = np.where(hit, r + rng.normal(0.0, cfg.range_noise, r.shape), np.nan)
    drop = hit & (rng.random(r.shape) < cfg.dropout)
    spur = hit & ~drop & (rng.random(r.shape) < cfg.spurious)
    r[spur] = rng.uniform(cfg.min_range, np.maximum(r[spur], cfg.min_range))
    keep = hit & ~drop
    scans = [d[f, keep[f]] * r[f, keep[f], None] for f in range(F)]
    counts = dict(
        rays=int(F * N),
        no_return=int((~hit).sum()),
        dropout=int(drop.sum()),
        spurious=int(spur.sum()),
    )
    return scans, counts


def observe_leds(
    scene, Tg: np.ndarray, Tc: np.ndarray, cam: CameraConfig, rng: np.random.Generator
):
    """LED pixels seen by the ceiling camera: (F,3,2) pixels (NaN where not seen) and (F,3)
    visibility (in front, inside the image, not occluded -- checked by ray casting camera ->
    LED)."""
    leds_w = np.einsum("fij,nj->fni", Tg[:, :3, :3], led_positions()) + Tg[:, None, :3, 3]
    T_wcam = Tc @ T_CEILING_CAMERA
    T_camw = np.linalg.inv(T_wcam)
    p_cam = np.einsum("fij,fnj->fni", T_camw[:, :3, :3], leds_w) + T_camw[:, None, :3, 3]
    uv, visible = cam.pinhole().project(p_cam.reshape(-1, 3))
    uv = uv.reshape(p_cam.shape[:2] + (2,)) + rng.normal(
        0.0, cam.pixel_noise, p_cam.shape[:2] + (2,)
    )
    visible = visible.reshape(p_cam.shape[:2])
    origin = np.broadcast_to(T_wcam[:, None, :3, 3], leds_w.shape)
    delta = leds_w - origin
    dist = np.linalg.norm(delta, axis=-1)
    hit = raycast(scene, origin.reshape(-1, 3), (delta / dist[..., None]).reshape(-1, 3)).reshape(
        dist.shape
    )
    visible &= ~(hit < dist - 0.02)
    uv[~visible] = np.nan
    return uv, visible
