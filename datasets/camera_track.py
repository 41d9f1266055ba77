"""The log writer of the camera-track scenarios: one camera robot watching the markers of a static
target (`markers`, odometry as `relative_pose3`, ground truth as TUM; docs/log_format.md)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.eval import write_tum
from graphloc.manifest import write_manifest
from graphloc.log_writer import write_table


@dataclass(frozen=True)
class CameraTrackLog:
    """One camera (robot `observer`, body frame = camera frame) watching the markers of a static
    `target` (layout (m,3) in the target's frame, the target at the world origin).
    times (T,); true camera poses R_wc (T,3,3), t_wc (T,3); pixels (T,m,2) noisy (NaN = not
    seen); camera: PinholeCamera; odometry: T-1 noisy relative poses (gtsam.Pose3) with their
    diagonal 6x6 covariances odometry_cov, or []; surface: (point, normal) of the plane the
    camera moves on, or None; identical_markers: the markers cannot be told apart (seed 001);
    meta: free-form."""

    name: str
    times: np.ndarray
    R_wc: np.ndarray
    t_wc: np.ndarray
    layout: np.ndarray
    pixels: np.ndarray
    camera: object
    pixel_sigma: float
    odometry: list
    odometry_cov: list
    observer: str = "climber"
    target: str = "ground"
    surface: tuple | None = None
    identical_markers: bool = False
    meta: dict = dataclasses.field(default_factory=dict)


def stack_poses(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(F,3,3) rotations, (F,3) translations -> (F,4,4) poses."""
    T = np.tile(np.eye(4), (len(R), 1, 1))
    T[:, :3, :3], T[:, :3, 3] = R, t
    return T


def pose7(R: np.ndarray, t: np.ndarray) -> list:
    """A manifest pose [x, y, z, qx, qy, qz, qw] of rotation R (3,3) and translation t (3,)."""
    return [*map(float, t), *map(float, Rotation.from_matrix(R).as_quat())]


def relative_pose3_rows(times, steps: list, covs: list) -> list:
    """`relative_pose3` rows (sensor "odometry") of steps[k]: pose k -> k + 1 (gtsam.Pose3)
    with its diagonal 6x6 covariance covs[k]."""
    rows = []
    for t0, t1, step, cov in zip(times[:-1], times[1:], steps, covs):
        qx, qy, qz, qw = Rotation.from_matrix(step.rotation().matrix()).as_quat()
        rows.append(
            (
                float(t1),
                "odometry",
                float(t0),
                *map(float, step.translation()),
                qx,
                qy,
                qz,
                qw,
                *map(float, np.sqrt(np.diag(cov))),
            )
        )
    return rows


def write_camera_track(log: CameraTrackLog, out_dir) -> Path:
    """Write `log` as a graphloc log directory (format version 2: markers, relative_pose3,
    groundtruth TUM); returns the manifest path."""
    out = Path(out_dir)
    obs = log.observer
    markers = [
        (float(tk), "camera", log.target, j, float(u), float(v))
        for tk, px in zip(log.times, log.pixels)
        for j, (u, v) in enumerate(px)
        if np.isfinite([u, v]).all()
    ]
    write_table(out / obs / "markers.csv", "markers", markers)
    tables = {"markers": f"{obs}/markers.csv", "groundtruth": f"{obs}/groundtruth.tum"}
    write_tum(out / obs / "groundtruth.tum", log.times, stack_poses(log.R_wc, log.t_wc))
    sensors = []
    if log.odometry:
        rows = relative_pose3_rows(log.times, log.odometry, log.odometry_cov)
        write_table(out / obs / "relative_pose3.csv", "relative_pose3", rows)
        tables["relative_pose3"] = f"{obs}/relative_pose3.csv"
        sensors.append({"name": "odometry", "type": "odometry"})
    cam = log.camera
    sensors.append(
        {
            "name": "camera",
            "type": "camera",
            "params": {**cam.params(), "pixel_sigma": log.pixel_sigma},
        }
    )
    climber = {
        "name": obs,
        "kind": "ceiling",
        "planar": False,
        "sensors": sensors,
        "tables": tables,
    }
    if log.surface is not None:
        climber["surface"] = {
            "point": [float(a) for a in log.surface[0]],
            "normal": [float(a) for a in log.surface[1]],
        }
    manifest = {
        "name": log.name,
        "robots": [
            climber,
            {
                "name": log.target,
                "kind": "ground",
                "static": True,
                "initial_pose": [0, 0, 0, 0, 0, 0, 1],
                "markers": np.asarray(log.layout, dtype=float).tolist(),
                "identical_markers": log.identical_markers,
                "sensors": [],
                "tables": {},
            },
        ],
        "meta": {"scenario": log.name, **log.meta},
    }
    return write_manifest(manifest, out)
