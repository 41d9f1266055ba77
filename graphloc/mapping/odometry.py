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

from graphloc.mapping.config import OdometryConfig


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


class ScanOdometry:
    """KISS-ICP's own pipeline (`KissICP`) over one scanner's sequence, one scan at a time:
    `add(points)` registers a scan onto the map of the scans before it and returns the step
    T_{k-1,k} from the previous scan (None for the first). A scan's step uses the scans before
    it only (causal), so the live team (`graphloc.live.event_rows.ScanFeed`) and the log reader
    (`datasets.log_observations.scan_odometry`) make the same steps."""

    def __init__(self, cfg: OdometryConfig = OdometryConfig()):
        self.kiss = KissICP(kiss_config(cfg))
        self.pose: np.ndarray | None = None  # the last scan's pose in KISS-ICP's frame
        self.frame: np.ndarray | None = None  # the last scan's points KISS-ICP kept
        self.count = 0

    def add(self, points, timestamps=None) -> np.ndarray | None:
        """Scan `count` ((N,3) finite points; `timestamps` (N,) per-point times in [0,1] for
        deskewing, zeros otherwise): its step from the previous scan, (4,4), or None."""
        f = self.count
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"KISS-ICP odometry: scan {f} has shape {pts.shape}, expected (N,3)")
        if not np.isfinite(pts).all():
            raise ValueError(f"KISS-ICP odometry: scan {f} contains NaN/inf points")
        ts = np.zeros(len(pts)) if timestamps is None else np.asarray(timestamps, np.float64)
        self.frame, _ = self.kiss.register_frame(pts, ts)
        previous, self.pose = self.pose, self.kiss.last_pose.copy()
        self.count += 1
        return None if previous is None else np.linalg.inv(previous) @ self.pose


def run_odometry(
    scans: list[np.ndarray], cfg: OdometryConfig = OdometryConfig(), timestamps=None
) -> OdometryResult:
    """KISS-ICP over a scan sequence (`ScanOdometry`, scan by scan) and the local map it
    implies. `timestamps`: optional per-scan (N_f,) per-point times in [0,1] for deskewing;
    zeros otherwise."""
    if len(scans) == 0:
        raise ValueError("run_odometry: empty scan sequence")
    start = time.perf_counter()
    odom = ScanOdometry(cfg)
    poses, clouds = [], []
    for f, pts in enumerate(scans):
        odom.add(pts, None if timestamps is None else timestamps[f])
        poses.append(odom.pose)
        clouds.append(odom.frame @ odom.pose[:3, :3].T + odom.pose[:3, 3])
    poses = np.asarray(poses)
    first_inv = np.linalg.inv(poses[0])
    poses = first_inv @ poses
    cloud = np.concatenate(clouds) @ first_inv[:3, :3].T + first_inv[:3, 3]
    pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(cloud.astype(np.float32)))
    local_map = pcd.voxel_down_sample(cfg.map_voxel).point.positions.numpy().astype(float)
    return OdometryResult(poses, local_map, time.perf_counter() - start)
