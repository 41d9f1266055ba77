"""Scenario `dual-robot-room`: seed 004 (Kaushik et al.) Sec. II-A / Fig. 1, 3: a ground robot
(LiDAR, LED triangle) and an inverted ceiling robot (LiDAR, downward camera) moving in a room
(`room_scene`); the run's files, its log, and `simulate_and_fuse`, the job of `graphloc demo`."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import ClassVar, Literal

import numpy as np
import open3d as o3d

from graphloc.config import parse_overrides
from graphloc.config_schema import config_dataclass, setting
from graphloc.datasets.room_scene import (
    FLIP_X,
    T_CEILING_CAMERA,
    VARIANTS,
    CameraConfig,
    LidarConfig,
    Room,
    led_positions,
    make_room,
    observe_leds,
    rot_z,
    scan_frames,
)
from graphloc.datasets.camera_track import pose7, stack_poses
from graphloc.eval import write_tum
from graphloc.log_writer import write_table
from graphloc.log_writer import write_csv
from graphloc.structured import dumps_json, read_json
from graphloc.pipelines.map_fusion.options import FusionConfig
from graphloc.pipelines.map_fusion.types import FusionInput, LedObservations
from graphloc.mapping.io import read_led_pixels, read_points, read_tum

ROBOTS = ("ground", "ceiling")


@config_dataclass
class DualRoomConfig:
    """One scenario: room variant, random placement/headings from `seed`, `frames` steps at
    `rate` Hz."""

    variant: Literal[VARIANTS] = "furnished"
    seed: int = 0
    frames: int = setting(8, ge=2, le=1000)
    rate: float = setting(5.0, gt=0.0, le=1000.0)
    ground_lidar_height: float = 0.35
    ceiling_gap: float = 0.08  # ceiling LiDAR centre below the ceiling plane
    ground_speed: float = setting(0.25, ge=0.0, le=10.0)  # [m/s]
    ceiling_speed: float = setting(0.3, ge=0.0, le=10.0)  # [m/s]
    # horizontal distance ceiling robot <-> ground robot at start: an oblique
    # view keeps P3P away from its near-degenerate overhead case
    min_offset: float = setting(0.6, ge=0.0)
    max_offset: float = setting(1.2, ge=0.0, le=10.0)
    lidar: LidarConfig = field(default_factory=LidarConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)

    def __post_init__(self):
        if not 0.0 <= self.min_offset <= self.max_offset:
            raise ValueError(
                f"DualRoomConfig.min_offset must be in [0, max_offset = {self.max_offset:g}], "
                f"got {self.min_offset}"
            )


def variant_config(variant: str, seed: int, **overrides) -> DualRoomConfig:
    """Default config of a variant (low_overlap: 4 m LiDAR range as in seed 004 Sec. IV.A, robots
    apart)."""
    kw: dict = dict(variant=variant, seed=seed)
    if variant == "low_overlap":
        kw.update(lidar=LidarConfig(max_range=4.0), max_offset=1.6)
    kw.update(overrides)
    return DualRoomConfig(**kw)


# ----------------------------------------------------------------------------- motion
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
    Tg = stack_poses(rot_z(yaw_g), np.column_stack([g_xy, np.full(F, cfg.ground_lidar_height)]))
    Tc = stack_poses(
        rot_z(yaw_c) @ FLIP_X, np.column_stack([c_xy, np.full(F, room.size[2] - cfg.ceiling_gap)])
    )
    return t, Tg, Tc


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
        """The run as map-fusion input (`graphloc.pipelines.map_fusion.types.FusionInput`, no ground
        truth): both robots' scans and the ceiling camera's LED pixels."""
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
        write_csv(out / "led_pixels.csv", ["frame", "time", "led", "u", "v"], self._led_rows())
        meta = dict(
            scenario="dual-robot-room",
            config=asdict(self.config),
            camera_K=self.config.camera.pinhole().K.tolist(),
            led_positions_ground=led_positions().tolist(),
            T_ceiling_camera=T_CEILING_CAMERA.tolist(),
            T_ground0_ceiling0=self.T_ground0_ceiling0.tolist(),
            counts=self.counts,
        )
        (out / "meta.json").write_text(dumps_json(meta, indent=1))
        o3d.io.write_triangle_mesh(str(out / "room.ply"), self.room.mesh())
        self.write_log(out)
        return out

    def _led_rows(self) -> list:
        """(frame, time, led, u, v) of every LED seen, as the files write them."""
        uv = self.led_pixels
        return [
            (f, f"{self.times[f]:.6f}", k, f"{uv[f, k, 0]:.4f}", f"{uv[f, k, 1]:.4f}")
            for f, k in zip(*np.nonzero(self.led_visible))
        ]

    def write_log(self, out: Path) -> Path:
        """The same run as a graphloc log beside the files above (scans, LED pixels as markers,
        ground truth): the ground robot's first pose anchors the world, the ceiling robot is
        placed by the LEDs and moves on the ceiling plane."""
        tables = {}
        for robot in ROBOTS:
            rows = [
                (f"{t:.6f}", "lidar", f"scans/{robot}/{f:06d}.ply")
                for f, t in enumerate(self.times)
            ]
            write_table(out / robot / "scans.csv", "scans", rows)
            tables[robot] = {"scans": f"{robot}/scans.csv", "groundtruth": f"poses_{robot}.tum"}
        rows = [(t, "camera", "ground", k, u, v) for _, t, k, u, v in self._led_rows()]
        write_table(out / "ceiling" / "markers.csv", "markers", rows)
        tables["ceiling"]["markers"] = "ceiling/markers.csv"
        cam = self.config.camera
        T0 = self.poses["ground"][0]
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
                    "initial_pose": pose7(T0[:3, :3], T0[:3, 3]),
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
        path.write_text(dumps_json(manifest, indent=1) + "\n")
        return path

    @staticmethod
    def load(in_dir) -> "DualRoomScenario":
        """Read a directory written by `write` (ValueError naming the file on anything
        malformed)."""
        src = Path(in_dir)
        meta_path = src / "meta.json"
        if not meta_path.is_file():
            raise FileNotFoundError(f"{meta_path}: missing (not a dual-robot-room directory)")
        meta = read_json(meta_path, what="dual-robot-room meta file")
        try:
            config = DualRoomConfig(**parse_overrides(DualRoomConfig, meta["config"]))
        except (KeyError, TypeError, ValueError) as exc:
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


def simulate_and_fuse(
    out_dir, variant: str = "furnished", seed: int = 0, frames: int = 10, config=FusionConfig()
) -> dict:
    """Simulate `dual-robot-room` (written to out_dir/scenario), fuse the two robots' maps
    (`graphloc.pipelines.map_fusion.run.fuse_and_write`), write the outputs; returns the report.
    Raises FusionRejected (after writing the "not fused" report) as `fuse_and_write` does."""
    # the fusion pipeline loads when a run fuses, not when `graphloc simulate` imports this module
    from graphloc.pipelines.map_fusion.run import fuse_and_write

    scenario = DualRoomScenario.simulate(variant_config(variant, seed, frames=frames))
    out = Path(out_dir)
    scenario.write(out / "scenario")
    scenario_info = {
        "name": "dual-robot-room",
        "variant": variant,
        "seed": seed,
        "frames": frames,
        "dir": str(out / "scenario"),
        "counts": scenario.counts,
    }
    return fuse_and_write(
        scenario.fusion_input(),
        out,
        config,
        scenario.times,
        truth=scenario.T_ground0_ceiling0,
        extra={"scenario": scenario_info},
    )
