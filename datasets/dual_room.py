"""`dual-robot-room`: a simulated room with a ground robot (3D LiDAR + three LEDs) and a
ceiling robot (upside down on the ceiling, 3D LiDAR + downward camera), both moving.

Seed 004 (Kaushik et al.), Sec. II.A / Fig. 1: LEDs P1..P3 on the ground robot form an
equilateral triangle of side 0.3048 m; the ceiling robot is inverted (~180 deg about x) and
at any yaw; its camera and laser frames have parallel axes and a small offset.
Sec. IV.A: scans carry noise and outliers (range noise, dropouts, spurious returns here).
Furniture tops are only visible from the ceiling (Sec. I, "furniture tops").

Scans are ray cast with Open3D's `o3d.t.geometry.RaycastingScene`, all frames in one call.
Frames: `ground` = ground LiDAR frame (z up); `ceiling` = ceiling LiDAR frame (z down, into
the room); `camera` = ceiling camera (z = optical axis, down), `T_ceiling_camera` apart.
Scans are motion-free snapshots (no deskewing needed).

    scenario = DualRoomScenario.simulate(DualRoomConfig(variant="furnished", seed=3))
    scenario.write("out/room")            # scans/*.ply, poses, LED pixels, ground truth
    same = DualRoomScenario.load("out/room")
"""

from __future__ import annotations

import csv
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation

from graphloc.cameras import PinholeCamera
from graphloc.config import parse_overrides
from graphloc.eval import write_tum
from graphloc.io import write_table
from graphloc.mapping.fusion import FusionInput, LedObservations
from graphloc.mapping.io import read_led_pixels, read_points, read_tum

VARIANTS = ("furnished", "empty", "rectangular", "low_overlap")
LED_SIDE = 0.3048  # seed 004 Sec. II.A
ROBOTS = ("ground", "ceiling")


@dataclass(frozen=True)
class LidarConfig:
    """Spinning 3D LiDAR: `beams` elevations in [elev_min, elev_max] deg, `azimuths` per turn."""

    beams: int = 48
    azimuths: int = 450
    elev_min_deg: float = -25.0
    elev_max_deg: float = 50.0
    min_range: float = 0.19  # seed 004 Sec. IV.A: 0.19 m .. 4 m
    max_range: float = 8.0
    range_noise: float = 0.005  # [m] 1-sigma along the ray
    dropout: float = 0.05  # probability a return is missing
    spurious: float = 0.005  # probability a return is replaced by a random shorter range


@dataclass(frozen=True)
class CameraConfig:
    """Downward pinhole camera of the ceiling robot (no distortion)."""

    width: int = 640
    height: int = 480
    fx: float = 500.0
    fy: float = 500.0
    cx: float = 320.0
    cy: float = 240.0
    pixel_noise: float = 0.3  # [px] 1-sigma

    def pinhole(self) -> PinholeCamera:
        return PinholeCamera(self.fx, self.fy, self.cx, self.cy, self.width, self.height)


@dataclass(frozen=True)
class DualRoomConfig:
    """One scenario: room variant, random placement/headings from `seed`, `frames` steps at
    `rate` Hz."""

    variant: str = "furnished"
    seed: int = 0
    frames: int = 8
    rate: float = 5.0
    ground_lidar_height: float = 0.35
    ceiling_gap: float = 0.08  # ceiling LiDAR centre below the ceiling plane
    ground_speed: float = 0.25  # [m/s]
    ceiling_speed: float = 0.3  # [m/s]
    min_offset: float = (
        0.6  # horizontal distance ceiling robot <-> ground robot at start: an oblique
    )
    max_offset: float = 1.2  # view keeps P3P away from its near-degenerate overhead case
    lidar: LidarConfig = field(default_factory=LidarConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)

    def __post_init__(self):
        if self.variant not in VARIANTS:
            raise ValueError(f"DualRoomConfig.variant {self.variant!r} not in {VARIANTS}")
        if self.frames < 2:
            raise ValueError(f"DualRoomConfig.frames must be >= 2 (got {self.frames})")
        if not 0 <= self.min_offset <= self.max_offset:
            raise ValueError(
                "DualRoomConfig needs 0 <= min_offset <= max_offset "
                f"(got {self.min_offset}, {self.max_offset})"
            )
        if not self.rate > 0:
            raise ValueError(f"DualRoomConfig.rate must be > 0 (got {self.rate})")

    @staticmethod
    def from_dict(d: dict) -> "DualRoomConfig":
        d = dict(d)
        lidar = LidarConfig(**d.pop("lidar", {}))
        camera = CameraConfig(**d.pop("camera", {}))
        return DualRoomConfig(lidar=lidar, camera=camera, **d)


# ----------------------------------------------------------------------------- geometry helpers


def _poses(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(F,3,3), (F,3) -> (F,4,4)."""
    T = np.tile(np.eye(4), (len(R), 1, 1))
    T[:, :3, :3], T[:, :3, 3] = R, t
    return T


def _rot_z(yaw: np.ndarray) -> np.ndarray:
    """(N,) yaw -> (N,3,3)."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.zeros(np.shape(yaw) + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


FLIP_X = np.diag([1.0, -1.0, -1.0])  # 180 deg about x: the ceiling robot is upside down


def _quat_xyzw(R: np.ndarray) -> list:
    return [float(a) for a in Rotation.from_matrix(R).as_quat()]


def led_positions() -> np.ndarray:
    """(3,3) LED centres P1..P3 in the ground LiDAR frame: equilateral, side 0.3048 m
    (seed 004 Fig. 1B), on a plate 0.12 m above the LiDAR centre."""
    r = LED_SIDE / np.sqrt(3.0)
    ang = np.deg2rad([0.0, 120.0, 240.0])
    return np.stack([r * np.cos(ang), r * np.sin(ang), np.full(3, 0.12)], axis=1)


T_CEILING_CAMERA = _poses(np.eye(3)[None], np.array([[0.10, 0.0, 0.04]]))[
    0
]  # camera in ceiling-LiDAR frame (axes parallel)


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


def variant_config(variant: str, seed: int, **overrides) -> DualRoomConfig:
    """Default config of a variant (low_overlap: 4 m LiDAR range as in seed 004 Sec. IV.A, robots
    apart)."""
    kw: dict = dict(variant=variant, seed=seed)
    if variant == "low_overlap":
        kw.update(lidar=LidarConfig(max_range=4.0), max_offset=1.6)
    kw.update(overrides)
    return DualRoomConfig(**kw)


# ----------------------------------------------------------------------------- simulation


def lidar_directions(cfg: LidarConfig, phase: np.ndarray) -> np.ndarray:
    """(F, beams*azimuths, 3) unit ray directions in the LiDAR frame; `phase` (F,) [rad] is each
    frame's random firing offset in azimuth (a spinning LiDAR is not synchronised to its frames)."""
    el = np.deg2rad(np.linspace(cfg.elev_min_deg, cfg.elev_max_deg, cfg.beams))
    az = np.linspace(0.0, 2 * np.pi, cfg.azimuths, endpoint=False)
    E, A = np.meshgrid(el, az, indexing="ij")
    E, A = E.reshape(1, -1), A.reshape(1, -1) + np.asarray(phase).reshape(-1, 1)
    E = np.broadcast_to(E, A.shape)
    return np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=-1)


def _raycast(scene, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
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
    r = _raycast(scene, origins.reshape(-1, 3), dirs_w.reshape(-1, 3)).reshape(F, N)
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


def _sample_start(room: Room, cfg: DualRoomConfig, rng: np.random.Generator):
    """Ground robot start (free, with a margin for its drive) and the ceiling robot above it."""
    margin = 0.5 + cfg.ground_speed * cfg.frames / cfg.rate
    for _ in range(10_000):
        g = rng.uniform([0, 0], room.size[:2])
        if not room.free(g, margin)[0]:
            continue
        ang, rad = rng.uniform(0, 2 * np.pi), rng.uniform(cfg.min_offset, cfg.max_offset)
        c = g + rad * np.array([np.cos(ang), np.sin(ang)])
        cm = 0.3 + cfg.ceiling_speed * cfg.frames / cfg.rate
        if np.all(c > cm) and np.all(c < np.asarray(room.size[:2]) - cm):
            return g, c
    raise ValueError(f"dual-robot-room {cfg.variant}: no free start found for seed {cfg.seed}")


def trajectories(room: Room, cfg: DualRoomConfig, rng: np.random.Generator):
    """(F,4,4) world poses of the ground LiDAR and the ceiling LiDAR: the ground robot drives a
    gentle arc, the ceiling robot a sinusoid (seed 004 Fig. 3), random headings."""
    F = cfg.frames
    t = np.arange(F) / cfg.rate
    g0, c0 = _sample_start(room, cfg, rng)
    yaw_g0, yaw_c0 = rng.uniform(-np.pi, np.pi, 2)
    turn = rng.uniform(-0.3, 0.3)
    yaw_g = yaw_g0 + turn * t
    step = cfg.ground_speed / cfg.rate
    heading = np.concatenate([[yaw_g0], yaw_g[:-1]])
    g_xy = (
        g0
        + np.cumsum(np.stack([np.cos(heading), np.sin(heading)], 1) * step, 0)
        - [np.cos(yaw_g0) * step, np.sin(yaw_g0) * step]
    )
    # ceiling: forward along yaw_c0 with a sideways sinusoid and a heading that follows it
    s = cfg.ceiling_speed * t
    lateral = 0.25 * np.sin(2 * np.pi * s / 1.0)
    fwd = np.array([np.cos(yaw_c0), np.sin(yaw_c0)])
    left = np.array([-np.sin(yaw_c0), np.cos(yaw_c0)])
    c_xy = c0 + s[:, None] * fwd + lateral[:, None] * left
    yaw_c = yaw_c0 + 0.4 * np.sin(2 * np.pi * s / 1.5)
    Tg = _poses(_rot_z(yaw_g), np.column_stack([g_xy, np.full(F, cfg.ground_lidar_height)]))
    Tc = _poses(
        _rot_z(yaw_c) @ FLIP_X, np.column_stack([c_xy, np.full(F, room.size[2] - cfg.ceiling_gap)])
    )
    return t, Tg, Tc


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
    hit = _raycast(scene, origin.reshape(-1, 3), (delta / dist[..., None]).reshape(-1, 3)).reshape(
        dist.shape
    )
    visible &= ~(hit < dist - 0.02)
    uv[~visible] = np.nan
    return uv, visible


@dataclass
class DualRoomScenario:
    """Everything one run produces. Poses are (F,4,4) world poses; scans are in the sensor frame."""

    config: DualRoomConfig
    room: Room
    times: np.ndarray
    poses: dict[str, np.ndarray]  # robot -> (F,4,4) ground-truth LiDAR poses in the room
    scans: dict[str, list[np.ndarray]]  # robot -> F arrays (N_f,3)
    led_pixels: np.ndarray  # (F,3,2) ceiling-camera pixels of P1..P3, NaN if not seen
    led_visible: np.ndarray  # (F,3) bool
    counts: dict = field(default_factory=dict)

    name: ClassVar[str] = "dual-robot-room"
    config_class: ClassVar[type] = DualRoomConfig

    @classmethod
    def generate(cls, out_dir, seed: int = 0, **overrides) -> Path:
        """`graphloc simulate dual-robot-room` (the scenario protocol): simulate the variant's
        default config (`variant_config`) with `overrides`, write it; the manifest path."""
        kw = parse_overrides(DualRoomConfig, overrides)
        kw.pop("seed", None)
        out = Path(out_dir)
        cls.simulate(variant_config(kw.pop("variant", "furnished"), seed, **kw)).write(out)
        return out / "manifest.json"

    @property
    def T_ground0_ceiling0(self) -> np.ndarray:
        """Ground truth inter-robot transform: ceiling first-frame LiDAR pose in the ground first
        frame."""
        return np.linalg.inv(self.poses["ground"][0]) @ self.poses["ceiling"][0]

    @staticmethod
    def simulate(config: DualRoomConfig) -> "DualRoomScenario":
        rng = np.random.default_rng(config.seed)
        room = make_room(config.variant)
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(room.mesh()))
        for attempt in range(100):  # placements where the camera sees all LEDs in >= 2 frames
            times, Tg, Tc = trajectories(room, config, rng)
            uv, vis = observe_leds(scene, Tg, Tc, config.camera, rng)
            if vis.all(1).sum() >= 2:
                break
        else:
            raise ValueError(
                f"dual-robot-room {config.variant} seed {config.seed}: "
                "LEDs never seen twice in 100 placements"
            )
        scans_g, counts_g = scan_frames(scene, Tg, config.lidar, rng)
        scans_c, counts_c = scan_frames(scene, Tc, config.lidar, rng)
        counts = {
            "placement_attempts": attempt + 1,
            "ground": counts_g,
            "ceiling": counts_c,
            "led_frames_all_visible": int(vis.all(1).sum()),
        }
        return DualRoomScenario(
            config,
            room,
            times,
            {"ground": Tg, "ceiling": Tc},
            {"ground": scans_g, "ceiling": scans_c},
            uv,
            vis,
            counts,
        )

    # ------------------------------------------------------------------ files
    def fusion_input(self):
        """The run as map-fusion input (`graphloc.mapping.fusion.FusionInput`, no ground truth):
        both robots' scans and the ceiling camera's LED pixels."""
        leds = LedObservations(
            self.config.camera.pinhole(), led_positions(), T_CEILING_CAMERA, self.led_pixels
        )
        return FusionInput(self.times, self.scans["ground"], self.scans["ceiling"], leds)

    def write(self, out_dir) -> Path:
        """scans/<robot>/<frame:06d>.ply, poses_<robot>.tum (ground truth, TUM), led_pixels.csv,
        meta.json (config, intrinsics, LED layout, extrinsic, ground truth transform, counts),
        room.ply."""
        out = Path(out_dir)
        for robot in ROBOTS:
            (out / "scans" / robot).mkdir(parents=True, exist_ok=True)
            for f, pts in enumerate(self.scans[robot]):
                pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(pts.astype(np.float32)))
                path = out / "scans" / robot / f"{f:06d}.ply"
                if not o3d.t.io.write_point_cloud(str(path), pcd):
                    raise OSError(f"could not write {path}")
            write_tum(out / f"poses_{robot}.tum", self.times, self.poses[robot])
        with open(out / "led_pixels.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["frame", "time", "led", "u", "v"])
            for f in range(len(self.times)):
                for k in range(3):
                    if self.led_visible[f, k]:
                        w.writerow(
                            [
                                f,
                                f"{self.times[f]:.6f}",
                                k,
                                f"{self.led_pixels[f, k, 0]:.4f}",
                                f"{self.led_pixels[f, k, 1]:.4f}",
                            ]
                        )
        meta = dict(
            scenario="dual-robot-room",
            config=asdict(self.config),
            camera_K=self.config.camera.pinhole().K.tolist(),
            led_positions_ground=led_positions().tolist(),
            T_ceiling_camera=T_CEILING_CAMERA.tolist(),
            T_ground0_ceiling0=self.T_ground0_ceiling0.tolist(),
            counts=self.counts,
        )
        (out / "meta.json").write_text(json.dumps(meta, indent=1))
        o3d.io.write_triangle_mesh(str(out / "room.ply"), self.room.mesh())
        self.write_log(out)
        return out

    def write_log(self, out: Path) -> Path:
        """The same run as a graphloc log (docs/log_format.md) beside the files above, so that
        `graphloc smooth` / `online` take it: each robot's scans (KISS-ICP odometry at load
        time), the ceiling camera's LED pixels on the ground robot (markers), ground truth
        (TUM). The ground robot's first pose anchors the world; the ceiling robot is placed by
        the LEDs and moves on the ceiling plane (its LiDAR centre `ceiling_gap` below it)."""
        tables = {}
        for robot in ROBOTS:
            rows = [
                (f"{t:.6f}", "lidar", f"scans/{robot}/{f:06d}.ply")
                for f, t in enumerate(self.times)
            ]
            write_table(out / robot / "scans.csv", "scans", rows)
            tables[robot] = {"scans": f"{robot}/scans.csv", "groundtruth": f"poses_{robot}.tum"}
        rows = [
            (
                f"{self.times[f]:.6f}",
                "camera",
                "ground",
                k,
                f"{self.led_pixels[f, k, 0]:.4f}",
                f"{self.led_pixels[f, k, 1]:.4f}",
            )
            for f in range(len(self.times))
            for k in range(3)
            if self.led_visible[f, k]
        ]
        write_table(out / "ceiling" / "markers.csv", "markers", rows)
        tables["ceiling"]["markers"] = "ceiling/markers.csv"
        cam = self.config.camera
        T0 = self.poses["ground"][0]
        q = _quat_xyzw(T0[:3, :3])
        height = self.room.size[2] - self.config.ceiling_gap
        manifest = {
            "format": "graphloc-log",
            "version": 2,
            "name": "dual-robot-room",
            "start_time": float(self.times[0]),
            "robots": [
                {
                    "name": "ground",
                    "kind": "ground",
                    "planar": False,
                    "initial_pose": [*map(float, T0[:3, 3]), *q],
                    "initial_sigma": [1e-3, 1e-3],
                    "markers": led_positions().tolist(),
                    "sensors": [{"name": "lidar", "type": "scanner"}],
                    "tables": tables["ground"],
                },
                {
                    "name": "ceiling",
                    "kind": "ceiling",
                    "planar": False,
                    "surface": {"point": [0.0, 0.0, float(height)], "normal": [0.0, 0.0, -1.0]},
                    "sensors": [
                        {"name": "lidar", "type": "scanner"},
                        {
                            "name": "camera",
                            "type": "camera",
                            "extrinsics": T_CEILING_CAMERA.tolist(),
                            "params": {**cam.pinhole().params(), "pixel_sigma": cam.pixel_noise},
                        },
                    ],
                    "tables": tables["ceiling"],
                },
            ],
            "meta": {"scenario": "dual-robot-room", "variant": self.config.variant},
        }
        path = out / "manifest.json"
        path.write_text(json.dumps(manifest, indent=1) + "\n")
        return path

    @staticmethod
    def load(in_dir) -> "DualRoomScenario":
        """Read a directory written by `write` (ValueError naming the file on anything
        malformed)."""
        src = Path(in_dir)
        meta_path = src / "meta.json"
        if not meta_path.is_file():
            raise FileNotFoundError(f"{meta_path}: missing (not a dual-robot-room directory)")
        try:
            meta = json.loads(meta_path.read_text())
            config = DualRoomConfig.from_dict(meta["config"])
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{meta_path}: malformed ({exc})") from None
        poses, scans, times = {}, {}, None
        for robot in ROBOTS:
            times_r, poses[robot] = read_tum(src / f"poses_{robot}.tum")
            times = times_r if times is None else times
            if len(times_r) != len(times) or not np.allclose(times_r, times):
                raise ValueError(
                    f"{src / f'poses_{robot}.tum'}: timestamps differ from poses_ground.tum"
                )
            files = sorted((src / "scans" / robot).glob("*.ply"))
            if len(files) != len(times):
                raise ValueError(
                    f"{src / 'scans' / robot}: {len(files)} scans for {len(times)} poses"
                )
            scans[robot] = [read_points(p) for p in files]
        uv = read_led_pixels(src / "led_pixels.csv", len(times))
        vis = np.isfinite(uv).all(-1)
        return DualRoomScenario(
            config, make_room(config.variant), times, poses, scans, uv, vis, meta.get("counts", {})
        )
