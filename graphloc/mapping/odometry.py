"""Per-robot LiDAR odometry with KISS-ICP (kiss_icp 1.3 python API: KissICP(config).register_frame)
and the local map it implies. Seed 004 registers one scan per robot; here each robot first builds
its own local map from its scan sequence, anchored at its first frame."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import open3d as o3d
from kiss_icp.config import KISSConfig
from kiss_icp.config.config import DataConfig, MappingConfig, RegistrationConfig
from kiss_icp.kiss_icp import KissICP

from graphloc.config import check


@dataclass(frozen=True)
class OdometryConfig:
    """KISS-ICP settings for indoor rooms (voxel_size ~ 1% of range as KISS-ICP's default rule)."""

    max_range: float = 8.0
    min_range: float = 0.19
    voxel_size: float = 0.08
    deskew: bool = (
        False  # simulated scans are motion-free; True for real spinning LiDARs (needs timestamps)
    )
    map_voxel: float = 0.03  # voxel of the accumulated local map
    threads: int = 1

    def __post_init__(self):
        check(
            self,
            interval={
                "max_range": (0.0, 1000.0, "(]"),
                "min_range": (0.0, "max_range", "[)"),
                "voxel_size": (1e-3, 10.0, "[]"),
                "map_voxel": (1e-3, 10.0, "[]"),
            },
            integer={"threads": (0, 256)},  # 0: KISS-ICP chooses
        )


@dataclass(frozen=True)
class OdometryResult:
    """poses: (F,4,4) LiDAR pose of each frame in the robot's first frame (poses[0] = I).
    local_map: (M,3) all frames' points in the first frame, voxel-downsampled. seconds: wall
    time."""

    poses: np.ndarray
    local_map: np.ndarray
    seconds: float

    def increments(self) -> np.ndarray:
        """(F-1,4,4) relative motions T_{k-1,k}."""
        return np.linalg.inv(self.poses[:-1]) @ self.poses[1:]


def kiss_config(cfg: OdometryConfig) -> KISSConfig:
    return KISSConfig(
        data=DataConfig(max_range=cfg.max_range, min_range=cfg.min_range, deskew=cfg.deskew),
        mapping=MappingConfig(voxel_size=cfg.voxel_size),
        registration=RegistrationConfig(max_num_threads=cfg.threads),
    )


def run_odometry(
    scans: list[np.ndarray], cfg: OdometryConfig = OdometryConfig(), timestamps=None
) -> OdometryResult:
    """KISS-ICP over a scan sequence. `timestamps`: optional per-scan (N_f,) per-point times in
    [0,1] for deskewing; zeros otherwise."""
    if len(scans) == 0:
        raise ValueError("run_odometry: empty scan sequence")
    start = time.perf_counter()
    odom = KissICP(kiss_config(cfg))
    poses, clouds = [], []
    for f, pts in enumerate(scans):
        pts = np.asarray(pts, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"run_odometry: scan {f} has shape {pts.shape}, expected (N,3)")
        if not np.isfinite(pts).all():
            raise ValueError(f"run_odometry: scan {f} contains NaN/inf points")
        ts = (
            np.zeros(len(pts))
            if timestamps is None
            else np.asarray(timestamps[f], dtype=np.float64)
        )
        frame, _ = odom.register_frame(pts, ts)
        poses.append(odom.last_pose.copy())
        clouds.append(frame @ odom.last_pose[:3, :3].T + odom.last_pose[:3, 3])
    poses = np.asarray(poses)
    first_inv = np.linalg.inv(poses[0])
    poses = first_inv @ poses
    cloud = np.concatenate(clouds) @ first_inv[:3, :3].T + first_inv[:3, 3]
    pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(cloud.astype(np.float32)))
    local_map = pcd.voxel_down_sample(cfg.map_voxel).point.positions.numpy().astype(float)
    return OdometryResult(poses, local_map, time.perf_counter() - start)
