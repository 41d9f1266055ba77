"""Seed 000 (000_05137a0a9c449be3.txt) Sec. VI-A as a log of measurements: the ground robots'
mutual bearings, C1 the reference with |T_12| as a range, the climbing camera's bearings of
the three and its straight move as odometry."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.cameras import PinholeCamera, angular_sigma
from graphloc.datasets.camera_track import relative_pose3_rows
from graphloc.eval import write_tum
from graphloc.io import write_manifest, write_table

GROUND = ("ground1", "ground2", "ground3")
STRAIGHT_ROT_SIGMA = 0.01  # [rad] heading change allowed by "moves straight" (seed 000 Sec. IV)
BASELINE_SIGMA = 1e-6  # [m] |T_12| is known (seed 000 Problem 1)


@dataclass(frozen=True)
class FormationLog:
    """One seed 000 Sec. VI-A trial. ground_R (3,3,3) world_R_camera and ground_t (3,3) of the
    ground robots (body = omni camera frame); mutual (3,3,3): mutual[i, j] unit bearing of
    robot j in robot i's frame (diagonal ignored), mutual_sigma [rad]; baseline: the known
    |T_12| [m] and baseline_sigma; times (T,), climber_R (T,3,3), climber_t (T,3): the
    climbing camera's true poses; climber_bearings (T,3,3): [snapshot, ground robot] unit
    bearings in the camera frame (NaN: not seen), climber_sigma [rad]; odometry: T-1 relative
    Pose3 with diagonal covariances odometry_cov (the motion assumption); meta: free-form."""

    name: str
    ground_R: np.ndarray
    ground_t: np.ndarray
    mutual: np.ndarray
    mutual_sigma: float
    baseline: float
    baseline_sigma: float
    times: np.ndarray
    climber_R: np.ndarray
    climber_t: np.ndarray
    climber_bearings: np.ndarray
    climber_sigma: float
    odometry: list
    odometry_cov: list
    meta: dict = dataclasses.field(default_factory=dict)


def _pose7(R: np.ndarray, t: np.ndarray) -> list:
    return [*map(float, t), *map(float, Rotation.from_matrix(R).as_quat())]


def _bearing_rows(time: float, sensor: str, bearings, names) -> list:
    return [
        (float(time), sensor, name, *map(float, b))
        for b, name in zip(bearings, names)
        if name is not None and np.isfinite(b).all()
    ]


def write_formation_log(log: FormationLog, out_dir) -> Path:
    """Write `log` as a graphloc log directory; returns the manifest path."""
    out = Path(out_dir)
    robots = []
    for i, name in enumerate(GROUND):
        names = [g if j != i else None for j, g in enumerate(GROUND)]
        write_table(
            out / name / "bearing.csv", "bearing", _bearing_rows(0.0, "omni", log.mutual[i], names)
        )
        write_tum(
            out / name / "groundtruth.tum", np.zeros(1), _matrix(log.ground_R[i], log.ground_t[i])
        )
        tables = {"bearing": f"{name}/bearing.csv", "groundtruth": f"{name}/groundtruth.tum"}
        sensors = [
            {"name": "omni", "type": "bearing", "params": {"bearing_sigma": log.mutual_sigma}}
        ]
        robot = {"name": name, "kind": "ground", "planar": False, "static": True}
        if i == 0:  # C1 is the reference; it knows |T_12|
            robot["initial_pose"] = _pose7(log.ground_R[0], log.ground_t[0])
            write_table(
                out / name / "range.csv", "range", [(0.0, "baseline", GROUND[1], log.baseline)]
            )
            tables["range"] = f"{name}/range.csv"
            sensors.append(
                {
                    "name": "baseline",
                    "type": "range",
                    "params": {"range_sigma": log.baseline_sigma, "range_sigma_per_m": 0.0},
                }
            )
        robots.append({**robot, "sensors": sensors, "tables": tables})
    rows = [
        row
        for t, b in zip(log.times, log.climber_bearings)
        for row in _bearing_rows(t, "camera", b, GROUND)
    ]
    write_table(out / "climber" / "bearing.csv", "bearing", rows)
    poses = np.stack([_matrix(R, t)[0] for R, t in zip(log.climber_R, log.climber_t)])
    write_tum(out / "climber" / "groundtruth.tum", np.asarray(log.times, float), poses)
    rel = relative_pose3_rows(log.times, log.odometry, log.odometry_cov)
    write_table(out / "climber" / "relative_pose3.csv", "relative_pose3", rel)
    climber = {
        "name": "climber",
        "kind": "ceiling",
        "planar": False,
        "sensors": [
            {"name": "odometry", "type": "odometry"},
            {"name": "camera", "type": "bearing", "params": {"bearing_sigma": log.climber_sigma}},
        ],
        "tables": {
            "bearing": "climber/bearing.csv",
            "relative_pose3": "climber/relative_pose3.csv",
            "groundtruth": "climber/groundtruth.tum",
        },
    }
    manifest = {
        "name": log.name,
        "robots": [climber, *robots],
        "meta": {"scenario": log.name, **log.meta},
    }
    return write_manifest(manifest, out)


def _matrix(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)[None].copy()
    T[0, :3, :3], T[0, :3, 3] = R, t
    return T


def table_i_formation(
    trials,
    triangle,
    n: int,
    pixel_sigma: float,
    step_sigma: float,
    name: str,
    meta: dict | None = None,
) -> FormationLog:
    """Trial n of seed 000 Table I (`graphloc.datasets.feng_deterministic`: the climbing
    camera's `StraightLineTrials` and the ground robots' `GroundTriangle`) as a FormationLog:
    the mutual bearings and the climber's pixels lifted to bearings, with their median angular
    sigma (`graphloc.cameras.angular_sigma`); the seed's motion assumption as odometry: the
    climber moves straight without turning (rotation held to STRAIGHT_ROT_SIGMA), by an unknown
    step (translation sigma `step_sigma`)."""
    K = trials.K
    camera = PinholeCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], 640, 480)
    pixels = trials.pixels[n]
    bearings, ok = camera.pixel_to_bearing(pixels.reshape(-1, 2))
    bearings = np.where(ok[:, None], bearings, np.nan).reshape(3, 3, 3)
    off = ~np.eye(3, dtype=bool)
    cov = np.diag([STRAIGHT_ROT_SIGMA**2] * 3 + [step_sigma**2] * 3)
    return FormationLog(
        name=name,
        ground_R=triangle.R[n],
        ground_t=trials.ground[n],
        mutual=triangle.bearings[n],
        mutual_sigma=float(np.nanmedian(triangle.bearing_sigma[n][off])),
        # float32: what a bag's sensor_msgs/Range carries, so the log and its bag form agree
        baseline=float(np.float32(np.linalg.norm(trials.ground[n, 1] - trials.ground[n, 0]))),
        baseline_sigma=BASELINE_SIGMA,
        times=np.arange(3, dtype=float),
        climber_R=trials.R_snapshots[n],
        climber_t=trials.positions[n],
        climber_bearings=bearings,
        climber_sigma=float(np.median(angular_sigma(camera, pixels, pixel_sigma))),
        odometry=[gtsam.Pose3()] * 2,
        odometry_cov=[cov] * 2,
        meta=meta or {},
    )
