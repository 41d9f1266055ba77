"""Seed 000 (000_05137a0a9c449be3.txt) Sec. VI-A as a log of measurements: the ground robots'
mutual bearings, C1 the reference with |T_12| as a range, the climbing camera's bearings of
the three and its straight move as odometry."""

from __future__ import annotations

from pathlib import Path

import gtsam
import numpy as np

from graphloc.cameras import PinholeCamera, angular_sigma
from graphloc.datasets.camera_track import pose7, relative_pose3_rows, stack_poses
from graphloc.eval import write_tum
from graphloc.manifest import write_manifest
from graphloc.log_writer import write_table

GROUND = ("ground1", "ground2", "ground3")
STRAIGHT_ROT_SIGMA = 0.01  # [rad] heading change allowed by "moves straight" (seed 000 Sec. IV)
BASELINE_SIGMA = 1e-6  # [m] |T_12| is known (seed 000 Problem 1)


def _bearing_rows(time: float, sensor: str, bearings, names) -> list:
    return [
        (float(time), sensor, name, *map(float, b))
        for b, name in zip(bearings, names)
        if name is not None and np.isfinite(b).all()
    ]


def write_table_i_trial(
    trials,
    triangle,
    n: int,
    pixel_sigma: float,
    step_sigma: float,
    log_name: str,
    out_dir,
    meta: dict | None = None,
) -> Path:
    """Trial n of seed 000 Table I (`StraightLineTrials`, `GroundTriangle`) as a log directory,
    bearings with their median angular sigma; the seed's motion assumption as odometry (straight,
    not turning, an unknown step of sigma `step_sigma`). Returns the manifest path."""
    out = Path(out_dir)
    off = ~np.eye(3, dtype=bool)
    ground_R, ground_t = triangle.R[n], trials.ground[n]
    mutual_sigma = float(np.nanmedian(triangle.bearing_sigma[n][off]))
    # float32: what a bag's sensor_msgs/Range carries, so the log and its bag form agree
    baseline = float(np.float32(np.linalg.norm(ground_t[1] - ground_t[0])))
    robots = []
    for i, name in enumerate(GROUND):
        names = [g if j != i else None for j, g in enumerate(GROUND)]
        rows = _bearing_rows(0.0, "omni", triangle.bearings[n][i], names)
        write_table(out / name / "bearing.csv", "bearing", rows)
        pose = stack_poses(ground_R[i][None], ground_t[i][None])
        write_tum(out / name / "groundtruth.tum", np.zeros(1), pose)
        tables = {"bearing": f"{name}/bearing.csv", "groundtruth": f"{name}/groundtruth.tum"}
        sensors = [{"name": "omni", "type": "bearing", "params": {"bearing_sigma": mutual_sigma}}]
        robot = {"name": name, "kind": "ground", "planar": False, "static": True}
        if i == 0:  # C1 is the reference; it knows |T_12|
            robot["initial_pose"] = pose7(ground_R[0], ground_t[0])
            write_table(out / name / "range.csv", "range", [(0.0, "baseline", GROUND[1], baseline)])
            tables["range"] = f"{name}/range.csv"
            sensors.append(
                {
                    "name": "baseline",
                    "type": "range",
                    "params": {"range_sigma": BASELINE_SIGMA, "range_sigma_per_m": 0.0},
                }
            )
        robots.append({**robot, "sensors": sensors, "tables": tables})
    K = trials.K
    camera = PinholeCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], 640, 480)
    pixels = trials.pixels[n]
    bearings, ok = camera.pixel_to_bearing(pixels.reshape(-1, 2))
    bearings = np.where(ok[:, None], bearings, np.nan).reshape(3, 3, 3)
    climber_sigma = float(np.median(angular_sigma(camera, pixels, pixel_sigma)))
    times = np.arange(3, dtype=float)
    rows = [row for t, b in zip(times, bearings) for row in _bearing_rows(t, "camera", b, GROUND)]
    write_table(out / "climber" / "bearing.csv", "bearing", rows)
    poses = stack_poses(trials.R_snapshots[n], trials.positions[n])
    write_tum(out / "climber" / "groundtruth.tum", times, poses)
    cov = np.diag([STRAIGHT_ROT_SIGMA**2] * 3 + [step_sigma**2] * 3)
    rel = relative_pose3_rows(times, [gtsam.Pose3()] * 2, [cov] * 2)
    write_table(out / "climber" / "relative_pose3.csv", "relative_pose3", rel)
    climber = {
        "name": "climber",
        "kind": "ceiling",
        "planar": False,
        "sensors": [
            {"name": "odometry", "type": "odometry"},
            {"name": "camera", "type": "bearing", "params": {"bearing_sigma": climber_sigma}},
        ],
        "tables": {
            "bearing": "climber/bearing.csv",
            "relative_pose3": "climber/relative_pose3.csv",
            "groundtruth": "climber/groundtruth.tum",
        },
    }
    manifest = {
        "name": log_name,
        "robots": [climber, *robots],
        "meta": {"scenario": log_name, **(meta or {})},
    }
    return write_manifest(manifest, out)
