"""Team logs in graphloc's log format (version 2), written from ``docs/log_format.md`` alone.

An independent generator: it never imports graphloc and was written without reading its source,
only ``docs/log_format.md``, ``docs/outputs.md``, ``docs/rosbag.md``, ``README.md`` and the seed
papers (000: mutual bearings and P3P of a climbing robot seeing three ground robots; 001: a
camera and four markers; 003: a robot base seen as an ellipse; 004: a ground and a ceiling
robot). Issue 48: logs that graphloc's own simulators did not write show where it is wrong.

Layouts (named presets, every random choice drawn from ``numpy.random.default_rng(seed)``):

- ``ceiling-markers``: a climber on a sloped ceiling (normal tilted 10-20 deg off vertical) with
  a downward camera watching five ground robots with distinct 3- and 4-marker layouts, two
  static (``initial_pose``) and three moving on biased wheel ``odometry`` (with an
  ``initial_pose``); markers leave the image; the camera jitters about its extrinsics.
- ``wall-bearings``: three static ground robots bearing each other (one with an
  ``initial_pose``, one ``range`` row between two of them) and a wall climber on
  ``relative_pose3`` bearing all three (~1000 poses, ~1300 bearings): the doc's "mutual
  bearings" and "resection" log shapes, and a speed benchmark input.
- ``mixed-team``: six robots (ground, static ground, ceiling, wall) with ``range``,
  ``range_bearing`` to known landmarks (``landmarks.csv``), ``bearing``, ``markers``,
  ``relative_pose``, ``relative_pose3`` and wheel ``odometry``.

Conventions chosen where the doc leaves them open (``CONVENTIONS``, also written into each
run's ``generator.json``): see that dict; the report of issue 48's outside-user run lists them
as defects of the doc.

Noise: every noise value stated in the manifest (sensor ``params``, table sigmas, landmark
sigmas) is the standard deviation of the Gaussian noise actually added. Two effects are left
out of the stated noise on purpose, and are small: the camera's per-frame jitter about its
extrinsics (``camera_jitter_deg``) and a systematic scale bias of wheel odometry
(``odometry_bias``).

CLI: ``python tests/foreign/team_generator.py --out DIR --seed N --layout NAME [--corrupt KIND]``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

LAYOUTS = ("ceiling-markers", "wall-bearings", "mixed-team")
CORRUPTIONS = (
    "swap-uv",
    "wrong-intrinsics",
    "wrong-layout",
    "wrong-layout-scale",
    "odometry-x2",
    "target-typo",
)

#: the columns of each table, as the "Tables" section of docs/log_format.md lists them
HEADERS = {
    "odometry": ["time", "sensor", "v", "omega"],
    "relative_pose": [
        "time", "sensor", "time0", "dx", "dy", "dtheta", "sigma_x", "sigma_y", "sigma_theta",
    ],
    "relative_pose3": [
        "time", "sensor", "time0", "tx", "ty", "tz", "qx", "qy", "qz", "qw",
        "sigma_rx", "sigma_ry", "sigma_rz", "sigma_tx", "sigma_ty", "sigma_tz",
    ],
    "range": ["time", "sensor", "target", "range"],
    "bearing": ["time", "sensor", "target", "x", "y", "z"],
    "range_bearing": ["time", "sensor", "target", "range", "bearing"],
    "markers": ["time", "sensor", "target", "marker", "u", "v"],
    "groundtruth": ["time", "x", "y", "theta"],
}  # fmt: skip

#: the sensor type each table's ``sensor`` must have (docs/log_format.md, "Tables")
SENSOR_TYPE = {
    "odometry": "odometry",
    "relative_pose": "odometry",
    "relative_pose3": "odometry",
    "range": "range",
    "bearing": "bearing",
    "range_bearing": "range_bearing",
    "markers": "camera",
}

#: what this generator assumes where docs/log_format.md is silent or ambiguous
CONVENTIONS = {
    "units": "SI: metres, seconds, radians (also extrinsics rpy); pixels for u, v",
    "rpy": "extrinsics {'xyz', 'rpy': [roll, pitch, yaw]}: body_T_sensor = "
    "Trans(xyz) * Rz(yaw) Ry(pitch) Rx(roll) (scipy from_euler('ZYX', [yaw, pitch, roll]))",
    "matrix_extrinsics": "--extrinsics matrix: the 4x4 body_T_sensor (maps sensor coordinates "
    "to body coordinates) as the value of 'extrinsics'",
    "camera_frame": "OpenCV: x right, y down, z forward (optical axis); u = column, v = row, "
    "pixel centres at integer coordinates, the image spans [0, width-1] x [0, height-1]",
    "quaternions": "[qx, qy, qz, qw] (initial_pose, relative_pose3, TUM), unit, Hamilton",
    "planar_robot": "body origin on the floor (z = 0), x forward, z up; theta = yaw about +z",
    "climber_body": "body origin on the surface plane (plane distance 0); body z along the "
    "surface's normal, which points away from the surface into the room (the doc's level "
    "ceiling example: normal [0, 0, -1], camera rpy [0, 0, 0] looks down)",
    "bearing_target": "a bearing or range row to a robot points at the target's body origin "
    "(the doc says so for range; assumed for bearing), from the sensor's origin",
    "range_bearing": "range = 3D distance sensor origin -> target point; bearing = azimuth "
    "atan2(y, x) of that direction in the sensor frame",
    "relative_pose3": "increment T(time0)^-1 T(time), noise T_meas = T_true * Exp(xi), "
    "xi ~ N(0, diag(sigma)^2) in GTSAM's Pose3 tangent order (rx, ry, rz, tx, ty, tz)",
    "relative_pose": "planar increment (dx, dy) in the frame at time0, dtheta wrapped; "
    "additive Gaussian noise of the row's sigmas",
    "odometry": "v, omega measured at the row time and held until the next row (the truth is "
    "integrated exactly as arcs under these held controls); white-noise densities: a row "
    "held for dt gets N(0, (density / sqrt(dt))^2) on v and omega",
    "bearing_noise": "the unit vector perturbed by N(0, bearing_sigma^2) along two "
    "orthonormal directions perpendicular to it, renormalised",
    "markers": "one row per marker inside the image and at least 5 cm in front of the "
    "camera after noise (also sets of fewer than 3 markers, as a detector would report them)",
    "static_groundtruth": "a static robot's ground truth: its one pose, repeated at 1 Hz",
    "start_time": "0.0, stated; every initial_pose is the exact true pose at time 0",
}


# --------------------------------------------------------------------------------------------
# configuration


@dataclass
class NoiseConfig:
    """Standard deviations of the noise added, stated as such in the manifest and tables."""

    pixel_sigma: float = 1.0
    bearing_sigma: float = 0.005
    omni_bearing_sigma: float = 0.008
    range_sigma: float = 0.03
    range_sigma_per_m: float = 0.01
    rb_bearing_sigma: float = 0.01
    density_v: float = 0.01
    density_w: float = 0.02
    #: one relative_pose3 step's sigmas, GTSAM order (rx, ry, rz [rad], tx, ty, tz [m])
    rel3_sigmas: tuple[float, ...] = (0.002, 0.002, 0.002, 0.004, 0.004, 0.004)
    #: one relative_pose step's sigma_x, sigma_y [m], sigma_theta [rad]
    rel2_sigmas: tuple[float, ...] = (0.006, 0.006, 0.004)
    landmark_sigma: float = 0.01


@dataclass
class GeneratorConfig:
    """What one generated run is; ``generate`` checks it."""

    layout: str = "ceiling-markers"
    seed: int = 0
    #: a corruption of ``CORRUPTIONS`` applied to the clean run of this seed, or None
    corrupt: str | None = None
    #: run length [s]; None: the layout's own (90, 200, 120 s)
    duration_s: float | None = None
    #: how sensor extrinsics are written: ``rpy`` ({xyz, rpy}) or ``matrix`` (4x4)
    extrinsics_form: str = "rpy"
    #: landmarks of ``mixed-team``: ``varied`` heights (0.2-1.8 m) or all at the ground
    #: robots' range-bearing sensor height (``sensor``)
    landmark_heights: str = "varied"
    #: per-frame rotation of the true camera about its nominal extrinsics [deg] (min, max)
    camera_jitter_deg: tuple[float, float] = (0.2, 0.5)
    #: wheel odometry scale bias (|v| share, |omega| share), sign drawn per robot
    odometry_bias: tuple[float, float] = (0.03, 0.04)
    #: camera frames this long after the pose times of the observer (0: synchronized)
    camera_offset_s: float = 0.0
    #: ``mixed-team``: the wall robot's bearing and range sensors, which also observe landmarks,
    #: mounted off its body origin (8 cm, 3 cm). graphloc at baba18c refuses a landmark bearing
    #: or range from a sensor offset from the body origin (the doc does not say so); default:
    #: both at the origin (rotated only), so the run is read
    landmark_sensor_offset: bool = False
    noise: NoiseConfig = field(default_factory=NoiseConfig)

    def check(self) -> None:
        if self.layout not in LAYOUTS:
            raise ValueError(f"layout {self.layout!r}: not one of {', '.join(LAYOUTS)}")
        if self.corrupt is not None and self.corrupt not in CORRUPTIONS:
            raise ValueError(f"corrupt {self.corrupt!r}: not one of {', '.join(CORRUPTIONS)}")
        if self.extrinsics_form not in ("rpy", "matrix"):
            raise ValueError(f"extrinsics_form {self.extrinsics_form!r}: 'rpy' or 'matrix'")
        if self.landmark_heights not in ("varied", "sensor"):
            raise ValueError(f"landmark_heights {self.landmark_heights!r}: 'varied' or 'sensor'")
        if self.duration_s is not None and not (10.0 <= self.duration_s <= 3600.0):
            raise ValueError(f"duration_s {self.duration_s}: must lie in [10, 3600] s")
        lo, hi = self.camera_jitter_deg
        if not (0.0 <= lo <= hi <= 5.0):
            raise ValueError(f"camera_jitter_deg {self.camera_jitter_deg}: 0 <= min <= max <= 5")
        if not all(0.0 <= b < 0.5 for b in self.odometry_bias):
            raise ValueError(f"odometry_bias {self.odometry_bias}: shares in [0, 0.5)")
        if not (0.0 <= self.camera_offset_s < 0.2):
            raise ValueError(f"camera_offset_s {self.camera_offset_s}: in [0, 0.2) s")


DEFAULT_DURATION = {"ceiling-markers": 90.0, "wall-bearings": 200.0, "mixed-team": 120.0}


# --------------------------------------------------------------------------------------------
# geometry


def rpy_matrix(rpy) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) of ``[roll, pitch, yaw]`` [rad]."""
    roll, pitch, yaw = rpy
    return Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()


def transform(rotation: np.ndarray, translation) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = translation
    return out


def inverse(pose: np.ndarray) -> np.ndarray:
    r = pose[:3, :3]
    return transform(r.T, -r.T @ pose[:3, 3])


def rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def skew(w) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def se3_exp(xi) -> np.ndarray:
    """Exp of a Pose3 tangent vector in GTSAM's order ``(rx, ry, rz, tx, ty, tz)``."""
    w, v = np.asarray(xi[:3], float), np.asarray(xi[3:], float)
    theta = float(np.linalg.norm(w))
    big_w = skew(w)
    if theta < 1e-9:
        jac = np.eye(3) + 0.5 * big_w
    else:
        jac = (
            np.eye(3)
            + (1.0 - math.cos(theta)) / theta**2 * big_w
            + (theta - math.sin(theta)) / theta**3 * big_w @ big_w
        )
    return transform(Rotation.from_rotvec(w).as_matrix(), jac @ v)


def quat_xyzw(rotation: np.ndarray) -> list[float]:
    q = Rotation.from_matrix(rotation).as_quat()  # scipy: (x, y, z, w)
    if q[3] < 0:
        q = -q
    return [float(c) for c in q]


@dataclass(frozen=True)
class Plane:
    """A surface a robot moves on: ``point`` and an in-plane basis with ``e1 x e2 = normal``."""

    point: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    normal: np.ndarray

    def pose(self, a: float, b: float, psi: float) -> np.ndarray:
        """World pose of a body at plane coordinates (a, b), heading psi about the normal."""
        basis = np.column_stack([self.e1, self.e2, self.normal])
        return transform(basis @ rot_z(psi), self.point + a * self.e1 + b * self.e2)


def floor_plane() -> Plane:
    return Plane(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0]))


def ceiling_plane(height: float, tilt: float, azimuth: float) -> Plane:
    """A ceiling through (0, 0, height) whose normal (pointing down into the room) is tilted
    ``tilt`` [rad] off vertical about the horizontal axis at ``azimuth``."""
    axis = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
    normal = Rotation.from_rotvec(axis * tilt).apply([0.0, 0.0, -1.0])
    x = np.array([1.0, 0.0, 0.0])
    e1 = x - (x @ normal) * normal
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    return Plane(np.array([0.0, 0.0, height]), e1, e2, normal)


def wall_plane(point, azimuth: float) -> Plane:
    """A vertical wall through ``point`` whose normal (into the room) is at ``azimuth``."""
    normal = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
    e2 = np.array([0.0, 0.0, 1.0])
    e1 = np.cross(e2, normal)
    return Plane(np.asarray(point, float), e1, e2, normal)


def arc(state, v: float, w: float, dt: float) -> np.ndarray:
    """Exact unicycle motion under constant (v, w) for dt."""
    a, b, psi = state
    if abs(w) < 1e-9:
        return np.array([a + v * dt * math.cos(psi), b + v * dt * math.sin(psi), psi])
    psi1 = psi + w * dt
    return np.array(
        [
            a + v / w * (math.sin(psi1) - math.sin(psi)),
            b - v / w * (math.cos(psi1) - math.cos(psi)),
            psi1,
        ]
    )


class Track:
    """A unicycle on a plane: controls ``(v, w)`` set at ``times`` and held until the next."""

    def __init__(self, plane: Plane, times, states, controls):
        self.plane = plane
        self.times = np.asarray(times, float)
        self.states = np.asarray(states, float)
        self.controls = np.asarray(controls, float)

    @property
    def static(self) -> bool:
        return len(self.times) == 1

    def planar(self, t: float) -> np.ndarray:
        k = max(0, int(np.searchsorted(self.times, t, side="right")) - 1)
        v, w = self.controls[k]
        return arc(self.states[k], v, w, t - self.times[k])

    def pose(self, t: float) -> np.ndarray:
        a, b, psi = self.planar(t)
        return self.plane.pose(a, b, psi)


def static_track(plane: Plane, a: float, b: float, psi: float) -> Track:
    return Track(plane, [0.0], [[a, b, psi]], [[0.0, 0.0]])


def drive(rng, plane: Plane, start, t_end: float, dt: float, region, speed: float, turn_max):
    """Waypoint driving inside ``region`` = (a_min, a_max, b_min, b_max) of the plane."""
    a0, a1, b0, b1 = region
    times = np.arange(0.0, t_end + 0.5 * dt, dt)
    state = np.asarray(start, float)
    waypoint = np.array([rng.uniform(a0, a1), rng.uniform(b0, b1)])
    states, controls = [], []
    for _ in times:
        if np.hypot(*(waypoint - state[:2])) < 0.35:
            waypoint = np.array([rng.uniform(a0, a1), rng.uniform(b0, b1)])
        err = wrap(math.atan2(waypoint[1] - state[1], waypoint[0] - state[0]) - state[2])
        w = float(np.clip(1.5 * err, -turn_max, turn_max))
        v = speed * float(np.clip(math.cos(err), 0.15, 1.0))
        states.append(state)
        controls.append([v, w])
        state = arc(state, v, w, dt)
    return Track(plane, times, states, controls)


def marker_layout(rng, count: int) -> np.ndarray:
    """Distinct markers on a ground robot: ``count`` points around the body, 15-60 cm high,
    at least 20 cm apart; four are never coplanar (>= 8 cm off the first three's plane)."""
    while True:
        angles = np.arange(count) * 2.0 * math.pi / count + rng.uniform(-0.35, 0.35, count)
        radius = rng.uniform(0.22, 0.4, count)
        pts = np.column_stack(
            [radius * np.cos(angles), radius * np.sin(angles), rng.uniform(0.15, 0.6, count)]
        )
        gaps = [np.linalg.norm(p - q) for i, p in enumerate(pts) for q in pts[i + 1 :]]
        if min(gaps) < 0.2:
            continue
        if count >= 4:
            n = np.cross(pts[1] - pts[0], pts[2] - pts[0])
            n /= np.linalg.norm(n)
            if abs((pts[3] - pts[0]) @ n) < 0.08:
                continue
        return pts


# --------------------------------------------------------------------------------------------
# the log in memory


@dataclass
class Robot:
    name: str
    kind: str
    track: Track
    planar: bool
    static: bool = False
    markers: np.ndarray | None = None
    initial_pose: bool = False
    surface: dict | None = None
    sensors: list[dict] = field(default_factory=list)
    #: sensor name -> nominal body_T_sensor
    mounts: dict[str, np.ndarray] = field(default_factory=dict)

    def pose(self, t: float) -> np.ndarray:
        return self.track.pose(t)


@dataclass
class Log:
    name: str
    robots: list[Robot]
    #: relative path -> (table name, rows); the header is HEADERS[table]
    tables: dict[str, tuple[str, list[list]]] = field(default_factory=dict)
    #: robot name -> {table name: relative path}
    owners: dict[str, dict[str, str]] = field(default_factory=dict)
    landmarks: dict[int, np.ndarray] = field(default_factory=dict)
    duration: float = 0.0

    def add(self, robot: str, table: str, rows: list[list]) -> None:
        path = f"{robot}/{table}.csv"
        if path in self.tables:
            self.tables[path][1].extend(rows)
        else:
            self.tables[path] = (table, list(rows))
            self.owners.setdefault(robot, {})[table] = path

    def robot(self, name: str) -> Robot:
        return next(r for r in self.robots if r.name == name)


# --------------------------------------------------------------------------------------------
# measurements


class Sim:
    """Measurement rows of one run: every noise draw comes from ``rng`` in a fixed order."""

    def __init__(self, config: GeneratorConfig, log: Log, rng):
        self.cfg = config
        self.noise = config.noise
        self.log = log
        self.rng = rng

    # sensors -----------------------------------------------------------------------------
    def mount(self, robot: Robot, name: str, kind: str, xyz, rpy, params=None) -> None:
        body_t_sensor = transform(rpy_matrix(rpy), xyz)
        robot.mounts[name] = body_t_sensor
        entry: dict = {"name": name, "type": kind}
        if self.cfg.extrinsics_form == "rpy":
            entry["extrinsics"] = {"xyz": [float(c) for c in xyz], "rpy": [float(c) for c in rpy]}
        else:
            entry["extrinsics"] = [[float(c) for c in row] for row in body_t_sensor]
        if params:
            entry["params"] = params
        robot.sensors.append(entry)

    def odometry_sensor(self, robot: Robot, name: str = "odom", wheel: bool = False) -> None:
        entry: dict = {"name": name, "type": "odometry"}
        if wheel:
            entry["params"] = {"density_v": self.noise.density_v, "density_w": self.noise.density_w}
        robot.sensors.append(entry)

    # rows ----------------------------------------------------------------------------------
    def wheel_odometry(self, robot: Robot, sensor: str = "odom") -> None:
        """Rows ``v, omega`` at the track's control times: true controls times (1 + bias) plus
        white noise of the stated densities; the bias signs are drawn per robot."""
        track = robot.track
        bias_v = self.cfg.odometry_bias[0] * self.rng.choice([-1.0, 1.0])
        bias_w = self.cfg.odometry_bias[1] * self.rng.choice([-1.0, 1.0])
        dts = np.diff(track.times)
        dts = np.append(dts, dts[-1])
        rows = []
        for t, (v, w), dt in zip(track.times, track.controls, dts):
            nv = self.noise.density_v / math.sqrt(dt)
            nw = self.noise.density_w / math.sqrt(dt)
            rows.append(
                [
                    t,
                    sensor,
                    v * (1.0 + bias_v) + self.rng.normal(0.0, nv),
                    w * (1.0 + bias_w) + self.rng.normal(0.0, nw),
                ]
            )
        self.log.add(robot.name, "odometry", rows)

    def relative_pose3(self, robot: Robot, times, sensor: str = "odom") -> None:
        sig = np.asarray(self.noise.rel3_sigmas, float)
        rows = []
        for t0, t1 in zip(times[:-1], times[1:]):
            delta = inverse(robot.pose(t0)) @ robot.pose(t1)
            meas = delta @ se3_exp(self.rng.normal(0.0, sig))
            rows.append([t1, sensor, t0, *meas[:3, 3], *quat_xyzw(meas[:3, :3]), *sig])
        self.log.add(robot.name, "relative_pose3", rows)

    def relative_pose(self, robot: Robot, times, sensor: str = "odom") -> None:
        sig = np.asarray(self.noise.rel2_sigmas, float)
        rows = []
        for t0, t1 in zip(times[:-1], times[1:]):
            x0, y0, p0 = robot.track.planar(t0)
            x1, y1, p1 = robot.track.planar(t1)
            c, s = math.cos(p0), math.sin(p0)
            d = np.array([c * (x1 - x0) + s * (y1 - y0), -s * (x1 - x0) + c * (y1 - y0)])
            n = self.rng.normal(0.0, sig)
            rows.append([t1, sensor, t0, d[0] + n[0], d[1] + n[1], wrap(p1 - p0) + n[2], *sig])
        self.log.add(robot.name, "relative_pose", rows)

    def _point(self, target: str, t: float) -> np.ndarray:
        if target.startswith("landmark:"):
            return self.log.landmarks[int(target.split(":", 1)[1])]
        return self.log.robot(target).pose(t)[:3, 3]

    def bearings(self, robot: Robot, sensor: str, targets, times, sigma, fov_deg=180.0):
        """Unit directions to each target's body origin (or landmark) in the sensor frame,
        for targets within ``fov_deg`` of the sensor's z axis."""
        rows = []
        cos_fov = math.cos(math.radians(fov_deg))
        for t in times:
            world_t_sensor = robot.pose(t) @ robot.mounts[sensor]
            for target in targets:
                d = world_t_sensor[:3, :3].T @ (self._point(target, t) - world_t_sensor[:3, 3])
                d /= np.linalg.norm(d)
                noisy = noisy_direction(self.rng, d, sigma)
                if d[2] >= cos_fov:
                    rows.append([t, sensor, target, *noisy])
        self.log.add(robot.name, "bearing", rows)

    def ranges(self, robot: Robot, sensor: str, targets, times, max_range=1e9, per_m=None):
        """Ranges from the sensor's origin to each target's body origin (or landmark), noise
        ``hypot(range_sigma, per_m * range)`` (``per_m`` default: the config's)."""
        per_m = self.noise.range_sigma_per_m if per_m is None else per_m
        rows = []
        for t in times:
            origin = (robot.pose(t) @ robot.mounts[sensor])[:3, 3]
            for target in targets:
                r = float(np.linalg.norm(self._point(target, t) - origin))
                sigma = math.hypot(self.noise.range_sigma, per_m * r)
                noisy = r + self.rng.normal(0.0, sigma)
                if r <= max_range:
                    rows.append([t, sensor, target, noisy])
        self.log.add(robot.name, "range", rows)

    def range_bearings(self, robot: Robot, sensor: str, targets, times, max_range, fov_deg):
        rows = []
        for t in times:
            world_t_sensor = robot.pose(t) @ robot.mounts[sensor]
            for target in targets:
                d = world_t_sensor[:3, :3].T @ (self._point(target, t) - world_t_sensor[:3, 3])
                r = float(np.linalg.norm(d))
                azimuth = math.atan2(d[1], d[0])
                sigma = math.hypot(self.noise.range_sigma, self.noise.range_sigma_per_m * r)
                noisy_r = r + self.rng.normal(0.0, sigma)
                noisy_b = wrap(azimuth + self.rng.normal(0.0, self.noise.rb_bearing_sigma))
                if r <= max_range and abs(azimuth) <= math.radians(fov_deg):
                    rows.append([t, sensor, target, noisy_r, noisy_b])
        self.log.add(robot.name, "range_bearing", rows)

    def markers(self, robot: Robot, sensor: str, camera: dict, targets, times) -> None:
        """Marker pixels of each target seen by the jittering camera: one row per marker in
        front of the camera and inside the image after noise."""
        k = np.array(
            [[camera["fx"], 0.0, camera["cx"]], [0.0, camera["fy"], camera["cy"]], [0, 0, 1.0]]
        )
        width, height = camera["width"], camera["height"]
        lo, hi = self.cfg.camera_jitter_deg
        rows = []
        for t in times:
            axis = self.rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            jitter = Rotation.from_rotvec(axis * math.radians(self.rng.uniform(lo, hi)))
            world_t_cam = robot.pose(t) @ robot.mounts[sensor] @ transform(jitter.as_matrix(), 0)
            cam_t_world = inverse(world_t_cam)
            for name in targets:
                target = self.log.robot(name)
                layout = target.markers
                pts_w = (target.pose(t) @ np.c_[layout, np.ones(len(layout))].T)[:3].T
                pts_c = (cam_t_world[:3, :3] @ pts_w.T).T + cam_t_world[:3, 3]
                noise = self.rng.normal(0.0, self.noise.pixel_sigma, (len(layout), 2))
                front = pts_c[:, 2] > 0.05
                if not front.any():
                    continue
                uv, _ = cv2.projectPoints(pts_c[front], np.zeros(3), np.zeros(3), k, None)
                uv = uv.reshape(-1, 2) + noise[front]
                for index, (u, v) in zip(np.flatnonzero(front), uv):
                    if 0.0 <= u <= width - 1 and 0.0 <= v <= height - 1:
                        rows.append([t, sensor, name, int(index), float(u), float(v)])
        self.log.add(robot.name, "markers", rows)


def noisy_direction(rng, d: np.ndarray, sigma: float) -> np.ndarray:
    helper = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else np.array([0, 1.0, 0])
    n1 = np.cross(d, helper)
    n1 /= np.linalg.norm(n1)
    n2 = np.cross(d, n1)
    e = d + sigma * (rng.normal() * n1 + rng.normal() * n2)
    return e / np.linalg.norm(e)


def camera_params(noise: NoiseConfig, fx=520.0, width=800, height=600) -> dict:
    return {
        "fx": fx,
        "fy": fx,
        "cx": (width - 1) / 2.0,
        "cy": (height - 1) / 2.0,
        "width": width,
        "height": height,
        "pixel_sigma": noise.pixel_sigma,
    }


def spread_points(rng, count, region, min_gap, tries=10000) -> list[np.ndarray]:
    a0, a1, b0, b1 = region
    for _ in range(tries):
        pts = [np.array([rng.uniform(a0, a1), rng.uniform(b0, b1)]) for _ in range(count)]
        if all(np.linalg.norm(p - q) >= min_gap for i, p in enumerate(pts) for q in pts[i + 1 :]):
            return pts
    raise RuntimeError("spread_points: region too small for the gap")


def frame_times(step: float, duration: float, offset: float = 0.0) -> np.ndarray:
    return np.round(np.arange(offset, duration - 1e-9, step), 6)


# --------------------------------------------------------------------------------------------
# layouts


def _ground(rng, sim: Sim, name: str, markers: int | None, *, moving: bool, duration: float,
            start=None, region=(-3.3, 3.3, -2.4, 2.4), speed=0.25) -> Robot:  # fmt: skip
    floor = floor_plane()
    if start is None:
        start = (rng.uniform(*region[:2]), rng.uniform(*region[2:]), rng.uniform(-math.pi, math.pi))
    if moving:
        track = drive(rng, floor, start, duration, 0.1, region, speed, 0.8)
    else:
        track = static_track(floor, *start)
    robot = Robot(name, "ground", track, planar=True, static=not moving, initial_pose=True)
    if markers:
        robot.markers = marker_layout(rng, markers)
    return robot


def _climber(rng, sim, name, kind, plane, duration, region, speed) -> Robot:
    start = (rng.uniform(*region[:2]) * 0.5, rng.uniform(*region[2:]) * 0.5, rng.uniform(-3, 3))
    track = drive(rng, plane, start, duration, 0.2, region, speed, 0.5)
    surface = {
        "point": [float(c) for c in plane.point],
        "normal": [float(c) for c in plane.normal],
    }
    robot = Robot(name, kind, track, planar=False, surface=surface)
    sim.odometry_sensor(robot)
    return robot


def build_ceiling_markers(cfg: GeneratorConfig, rng, duration: float) -> Log:
    log = Log(f"foreign-ceiling-markers-s{cfg.seed}", [], duration=duration)
    sim = Sim(cfg, log, rng)
    tilt = math.radians(rng.uniform(10.0, 20.0))
    ceiling = ceiling_plane(3.0, tilt, rng.uniform(-math.pi, math.pi))
    climber = _climber(rng, sim, "climber", "ceiling", ceiling, duration, (-1.4, 1.4, -0.9, 0.9),
                       0.12)  # fmt: skip
    cam = camera_params(cfg.noise)
    sim.mount(climber, "camera", "camera", [0.12, -0.03, 0.06],
              [0.04, -0.06, rng.uniform(-math.pi, math.pi)], cam)  # fmt: skip
    anchors = spread_points(rng, 2, (-1.2, 1.2, -0.8, 0.8), 1.1)
    ground = [
        _ground(rng, sim, "anchor3", 3, moving=False, duration=duration,
                start=(*anchors[0], rng.uniform(-math.pi, math.pi))),
        _ground(rng, sim, "anchor4", 4, moving=False, duration=duration,
                start=(*anchors[1], rng.uniform(-math.pi, math.pi))),
        _ground(rng, sim, "rover3", 3, moving=True, duration=duration),
        _ground(rng, sim, "rover4", 4, moving=True, duration=duration),
        _ground(rng, sim, "rover4b", 4, moving=True, duration=duration),
    ]  # fmt: skip
    log.robots = [climber, *ground]
    poses = frame_times(0.2, duration + 0.2)
    sim.relative_pose3(climber, poses)
    for robot in ground:
        if not robot.static:
            sim.odometry_sensor(robot, wheel=True)
            sim.wheel_odometry(robot)
    frames = frame_times(0.2, duration, cfg.camera_offset_s)
    sim.markers(climber, "camera", cam, [r.name for r in ground], frames)
    return log


def build_wall_bearings(cfg: GeneratorConfig, rng, duration: float) -> Log:
    log = Log(f"foreign-wall-bearings-s{cfg.seed}", [], duration=duration)
    sim = Sim(cfg, log, rng)
    wall = wall_plane([0.0, 0.0, 1.8], rng.uniform(-0.4, 0.4))
    climber = _climber(rng, sim, "waller", "wall", wall, duration, (-1.6, 1.6, -0.7, 0.8), 0.08)
    sim.mount(climber, "cam", "bearing", [0.08, 0.0, 0.04], [0.05, -0.1, rng.uniform(-3, 3)],
              {"bearing_sigma": cfg.noise.bearing_sigma})  # fmt: skip
    # three ground robots 1.8-5 m out from the wall, a well-shaped triangle
    while True:
        spots = spread_points(rng, 3, (1.8, 5.0, -2.5, 2.5), 1.6)
        sides = [np.linalg.norm(spots[i] - spots[j]) for i, j in ((0, 1), (1, 2), (0, 2))]
        a, b, c = sides
        angles = [
            math.acos(np.clip((b * b + c * c - a * a) / (2 * b * c), -1, 1)),
            math.acos(np.clip((a * a + c * c - b * b) / (2 * a * c), -1, 1)),
        ]
        angles.append(math.pi - sum(angles))
        if min(angles) > math.radians(25):
            break
    floor_origin = np.array([wall.point[0], wall.point[1], 0.0])
    ground = []
    for i, (d, lateral) in enumerate(spots, start=1):
        xy = floor_origin + d * wall.normal + lateral * wall.e1
        robot = _ground(rng, sim, f"g{i}", None, moving=False, duration=duration,
                        start=(xy[0], xy[1], rng.uniform(-math.pi, math.pi)))  # fmt: skip
        robot.initial_pose = i == 1
        sim.mount(robot, "omni", "bearing", [0.0, 0.0, 0.25], [0.0, 0.0, rng.uniform(-3, 3)],
                  {"bearing_sigma": cfg.noise.omni_bearing_sigma})  # fmt: skip
        ground.append(robot)
    sim.mount(ground[0], "tape", "range", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0],
              {"range_sigma": cfg.noise.range_sigma, "range_sigma_per_m": 0.0})  # fmt: skip
    log.robots = [climber, *ground]
    sim.relative_pose3(climber, frame_times(0.2, duration + 0.2))
    names = [r.name for r in ground]
    mutual = frame_times(4.0, duration)
    for robot in ground:
        others = [n for n in names if n != robot.name]
        sim.bearings(robot, "omni", others, mutual, cfg.noise.omni_bearing_sigma)
    sim.ranges(ground[0], "tape", [names[1]], [0.0], per_m=0.0)
    sim.bearings(climber, "cam", names, frame_times(0.6, duration, cfg.camera_offset_s),
                 cfg.noise.bearing_sigma, fov_deg=80.0)  # fmt: skip
    return log


def build_mixed_team(cfg: GeneratorConfig, rng, duration: float) -> Log:
    log = Log(f"foreign-mixed-team-s{cfg.seed}", [], duration=duration)
    sim = Sim(cfg, log, rng)
    noise = cfg.noise
    # eight known landmarks on the room's walls
    lm_xy = [(-4.5, -3.0), (-4.5, 2.5), (-1.0, 3.6), (2.5, 3.6), (4.6, 1.0), (4.6, -2.5),
             (1.0, -3.6), (-2.5, -3.6)]  # fmt: skip
    for i, (x, y) in enumerate(lm_xy):
        z = rng.uniform(0.2, 1.8) if cfg.landmark_heights == "varied" else 0.3
        log.landmarks[11 + i] = np.array(
            [x + rng.uniform(-0.2, 0.2), y + rng.uniform(-0.2, 0.2), z]
        )
    landmarks = [f"landmark:{i}" for i in sorted(log.landmarks)]
    base = _ground(
        rng,
        sim,
        "base",
        4,
        moving=False,
        duration=duration,
        start=(rng.uniform(-0.8, 0.8), rng.uniform(-0.6, 0.6), rng.uniform(-3, 3)),
    )
    rover_a = _ground(rng, sim, "rover_a", 3, moving=True, duration=duration)
    rover_b = _ground(rng, sim, "rover_b", 4, moving=True, duration=duration)
    rover_c = _ground(rng, sim, "rover_c", 4, moving=True, duration=duration)
    ceiling = ceiling_plane(3.0, math.radians(rng.uniform(10, 20)), rng.uniform(-math.pi, math.pi))
    climber = _climber(
        rng, sim, "ceiling", "ceiling", ceiling, duration, (-1.4, 1.4, -0.9, 0.9), 0.12
    )
    wall = wall_plane([-4.9, 0.0, 1.8], rng.uniform(-0.25, 0.25))
    waller = _climber(rng, sim, "wall", "wall", wall, duration, (-2.0, 2.0, -0.7, 0.8), 0.1)
    waller.initial_pose = True
    log.robots = [base, rover_a, rover_b, rover_c, climber, waller]  # fmt: skip

    rb_params = {
        "range_sigma": noise.range_sigma,
        "range_sigma_per_m": noise.range_sigma_per_m,
        "bearing_sigma": noise.rb_bearing_sigma,
    }
    range_params = {"range_sigma": noise.range_sigma, "range_sigma_per_m": noise.range_sigma_per_m}
    cam = camera_params(noise)
    sim.odometry_sensor(rover_a, wheel=True)
    sim.mount(rover_a, "lidar", "range_bearing", [0.1, 0.0, 0.3], [0, 0, 0], rb_params)
    sim.odometry_sensor(rover_b)
    sim.mount(rover_b, "lidar", "range_bearing", [0.1, 0.0, 0.3], [0, 0, 0], rb_params)
    sim.mount(rover_b, "uwb", "range", [0.0, 0.0, 0.2], [0, 0, 0], range_params)
    sim.odometry_sensor(rover_c, wheel=True)
    sim.mount(
        rover_c,
        "omni",
        "bearing",
        [0.0, 0.0, 0.3],
        [0, 0, rng.uniform(-3, 3)],
        {"bearing_sigma": noise.omni_bearing_sigma},
    )
    sim.mount(
        climber,
        "camera",
        "camera",
        [0.1, 0.02, 0.05],
        [-0.03, 0.05, rng.uniform(-math.pi, math.pi)],
        cam,
    )
    off = 1.0 if cfg.landmark_sensor_offset else 0.0
    sim.mount(
        waller,
        "cam",
        "bearing",
        [0.08 * off, 0.0, 0.04 * off],
        [0.05, -0.1, rng.uniform(-3, 3)],
        {"bearing_sigma": noise.bearing_sigma},
    )
    sim.mount(waller, "uwb", "range", [0.0, 0.0, 0.03 * off], [0, 0, 0], range_params)

    sim.wheel_odometry(rover_a)
    sim.relative_pose(rover_b, frame_times(0.2, duration + 0.2))
    sim.wheel_odometry(rover_c)
    sim.relative_pose3(climber, frame_times(0.2, duration + 0.2))
    sim.relative_pose3(waller, frame_times(0.2, duration + 0.2))
    half = frame_times(0.5, duration)
    sim.range_bearings(rover_a, "lidar", landmarks, half, 6.0, 120.0)
    sim.range_bearings(rover_b, "lidar", landmarks, half, 6.0, 120.0)
    sim.ranges(rover_b, "uwb", ["rover_a", "base"], frame_times(1.0, duration))
    sim.bearings(
        rover_c,
        "omni",
        ["rover_a", "rover_b", "base"],
        frame_times(1.0, duration),
        noise.omni_bearing_sigma,
    )
    ground = ["base", "rover_a", "rover_b", "rover_c"]
    sim.markers(climber, "camera", cam, ground, frame_times(0.2, duration, cfg.camera_offset_s))
    sim.bearings(
        waller,
        "cam",
        ground + landmarks,
        frame_times(0.6, duration, cfg.camera_offset_s),
        noise.bearing_sigma,
        80.0,
    )
    sim.ranges(waller, "uwb", landmarks, frame_times(1.0, duration), max_range=7.0)
    return log


BUILDERS = {
    "ceiling-markers": build_ceiling_markers,
    "wall-bearings": build_wall_bearings,
    "mixed-team": build_mixed_team,
}


# --------------------------------------------------------------------------------------------
# corruptions


def _typo(name: str, taken) -> str:
    """A misspelling of ``name``: two neighbouring letters swapped (else a letter doubled)."""
    for i in range(1, len(name) - 1):
        cand = name[:i] + name[i + 1] + name[i] + name[i + 2 :]
        if cand != name and cand not in taken:
            return cand
    return name + name[-1]


def corrupt(log: Log, kind: str) -> dict:
    """Apply corruption ``kind`` to the clean ``log`` in place; returns what was changed.

    - ``swap-uv``: in every ``markers`` table, the values of the ``u`` and ``v`` columns are
      swapped (header unchanged).
    - ``wrong-intrinsics``: ``fx`` and ``fy`` of every camera in the manifest times 1.2 (the
      pixels stay those of the true camera).
    - ``wrong-layout``: the manifest's marker layout of the target with the most marker rows
      is permuted cyclically (marker i is given the coordinates of marker i-1).
    - ``wrong-layout-scale``: that layout scaled by 1.3 about the body origin.
    - ``odometry-x2``: one robot's odometry table values times 2: the first robot (by name)
      with a wheel ``odometry`` table (``v`` and ``omega``), else one with ``relative_pose``
      (``dx, dy, dtheta``), else one with ``relative_pose3`` (translation and rotation angle).
    - ``target-typo``: in the table with the most rows that target robots, every robot name in
      the ``target`` column is misspelled (two neighbouring letters swapped).
    """
    changed: dict = {"kind": kind}
    if kind == "swap-uv":
        touched = []
        for path, (table, rows) in log.tables.items():
            if table == "markers":
                for row in rows:
                    row[4], row[5] = row[5], row[4]
                touched.append(path)
        changed["tables"] = touched
    elif kind == "wrong-intrinsics":
        touched = []
        for robot in log.robots:
            for sensor in robot.sensors:
                if sensor["type"] == "camera":
                    sensor["params"] = dict(sensor["params"])
                    sensor["params"]["fx"] *= 1.2
                    sensor["params"]["fy"] *= 1.2
                    touched.append(f"{robot.name}/{sensor['name']}")
        changed["sensors"] = touched
    elif kind in ("wrong-layout", "wrong-layout-scale"):
        counts: dict[str, int] = {}
        for table, rows in log.tables.values():
            if table == "markers":
                for row in rows:
                    counts[row[2]] = counts.get(row[2], 0) + 1
        target = max(sorted(counts), key=lambda n: counts[n])
        robot = log.robot(target)
        before = robot.markers.copy()
        if kind == "wrong-layout":
            robot.markers = np.roll(robot.markers, 1, axis=0)
        else:
            robot.markers = robot.markers * 1.3
        changed.update(target=target, true_layout=before.tolist(), written=robot.markers.tolist())
    elif kind == "odometry-x2":
        for table, columns in (
            ("odometry", (2, 3)),
            ("relative_pose", (3, 4, 5)),
            ("relative_pose3", None),
        ):
            owners = sorted(r for r, tables in log.owners.items() if table in tables)
            if not owners:
                continue
            path = log.owners[owners[0]][table]
            rows = log.tables[path][1]
            for row in rows:
                if columns is not None:
                    for c in columns:
                        row[c] *= 2.0
                else:
                    row[3:6] = [2.0 * x for x in row[3:6]]
                    rotvec = Rotation.from_quat(row[6:10]).as_rotvec() * 2.0
                    row[6:10] = quat_xyzw(Rotation.from_rotvec(rotvec).as_matrix())
            changed.update(robot=owners[0], table=path)
            break
    elif kind == "target-typo":
        names = {r.name for r in log.robots}
        best, best_count = None, 0
        for path, (table, rows) in sorted(log.tables.items()):
            n = sum(1 for row in rows if len(row) > 2 and row[2] in names)
            if table in ("range", "bearing", "range_bearing", "markers") and n > best_count:
                best, best_count = path, n
        typos = {}
        for row in log.tables[best][1]:
            if row[2] in names:
                typos.setdefault(row[2], _typo(row[2], names))
                row[2] = typos[row[2]]
        changed.update(table=best, rows=best_count, typos=typos)
    else:
        raise ValueError(f"corrupt {kind!r}: not one of {', '.join(CORRUPTIONS)}")
    return changed


# --------------------------------------------------------------------------------------------
# writing


def _fmt(value, column: str) -> str:
    if isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return str(int(value))
    if column in ("time", "time0"):
        return f"{float(value):.6f}"
    return f"{float(value):.12g}"


def _truth_rows(robot: Robot, duration: float):
    step = 1.0 if robot.track.static else 0.1
    for t in np.round(np.arange(0.0, duration + 0.5 * step, step), 6):
        yield float(t), robot.pose(float(t)), robot.track.planar(float(t))


def _manifest_robot(robot: Robot, tables: dict[str, str]) -> dict:
    entry: dict = {"name": robot.name, "kind": robot.kind, "planar": robot.planar}
    if robot.static:
        entry["static"] = True
    if robot.initial_pose:
        if robot.planar:
            a, b, psi = robot.track.planar(0.0)
            entry["initial_pose"] = [float(a), float(b), float(wrap(psi))]
        else:
            pose = robot.pose(0.0)
            entry["initial_pose"] = [*map(float, pose[:3, 3]), *quat_xyzw(pose[:3, :3])]
    if robot.surface is not None:
        entry["surface"] = robot.surface
    if robot.markers is not None:
        entry["markers"] = [[round(float(c), 6) for c in p] for p in robot.markers]
    entry["sensors"] = robot.sensors
    entry["tables"] = dict(tables)
    return entry


def write_log(log: Log, out_dir: Path, meta: dict) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    robots = []
    for robot in log.robots:
        tables = dict(log.owners.get(robot.name, {}))
        (out_dir / robot.name).mkdir(exist_ok=True)
        if robot.planar:
            path = f"{robot.name}/groundtruth.csv"
            with open(out_dir / path, "w", newline="\n") as fh:
                fh.write(",".join(HEADERS["groundtruth"]) + "\n")
                for t, _, (a, b, psi) in _truth_rows(robot, log.duration):
                    fh.write(f"{t:.6f},{a:.9f},{b:.9f},{wrap(psi):.9f}\n")
        else:
            path = f"{robot.name}/groundtruth.tum"
            with open(out_dir / path, "w", newline="\n") as fh:
                for t, pose, _ in _truth_rows(robot, log.duration):
                    q = quat_xyzw(pose[:3, :3])
                    vals = [*pose[:3, 3], *q]
                    fh.write(f"{t:.6f} " + " ".join(f"{v:.9f}" for v in vals) + "\n")
        tables["groundtruth"] = path
        robots.append(_manifest_robot(robot, tables))
    for path, (table, rows) in log.tables.items():
        header = HEADERS[table]
        rows.sort(key=lambda row: row[0])  # stable: equal times keep their order
        with open(out_dir / path, "w", newline="\n") as fh:
            fh.write(",".join(header) + "\n")
            for row in rows:
                fh.write(",".join(_fmt(v, c) for v, c in zip(row, header)) + "\n")
    manifest: dict = {
        "format": "graphloc-log",
        "version": 2,
        "name": log.name,
        "start_time": 0.0,
        "robots": robots,
    }
    if log.landmarks:
        sigma = meta["config"]["noise"]["landmark_sigma"]
        with open(out_dir / "landmarks.csv", "w", newline="\n") as fh:
            fh.write("id,x,y,z,sigma_x,sigma_y,sigma_z\n")
            for lid, p in sorted(log.landmarks.items()):
                fh.write(f"{lid},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f},{sigma},{sigma},{sigma}\n")
        manifest["landmarks"] = {"file": "landmarks.csv"}
    manifest["meta"] = {"scenario": meta["config"]["layout"], "seed": meta["config"]["seed"],
                        "generator": "tests/foreign/team_generator.py"}  # fmt: skip
    (out_dir / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    (out_dir / "generator.json").write_text(json.dumps(meta, indent=1) + "\n")


def build(config: GeneratorConfig) -> Log:
    """The clean log of ``config`` in memory (no corruption applied)."""
    config.check()
    duration = config.duration_s or DEFAULT_DURATION[config.layout]
    rng = np.random.default_rng(config.seed)
    return BUILDERS[config.layout](config, rng, float(duration))


def generate(out_dir, config: GeneratorConfig) -> Path:
    """Write the run of ``config`` into ``out_dir`` (created; must be empty if it exists)."""
    out_dir = Path(out_dir)
    if out_dir.exists() and any(out_dir.iterdir()):
        raise FileExistsError(f"{out_dir}: exists and is not empty")
    log = build(config)
    meta: dict = {"config": asdict(config), "conventions": CONVENTIONS}
    true_layouts = {r.name: r.markers.tolist() for r in log.robots if r.markers is not None}
    meta["true_layouts"] = true_layouts
    if config.corrupt is not None:
        meta["corruption"] = corrupt(log, config.corrupt)
        log.name += f"-{config.corrupt}"
    write_log(log, out_dir, meta)
    return out_dir


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", required=True, help="run directory to write (new or empty)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--layout", choices=LAYOUTS, default="ceiling-markers")
    parser.add_argument("--corrupt", choices=CORRUPTIONS, default=None)
    parser.add_argument("--duration", type=float, default=None, help="run length [s]")
    parser.add_argument("--extrinsics", choices=("rpy", "matrix"), default="rpy")
    parser.add_argument("--landmark-heights", choices=("varied", "sensor"), default="varied")
    parser.add_argument("--camera-offset", type=float, default=0.0,
                        help="camera frames this long after the pose times [s]")  # fmt: skip
    parser.add_argument("--landmark-sensor-offset", action="store_true",
                        help="mixed-team: the wall robot's landmark bearings and ranges from "
                        "sensors off its body origin")  # fmt: skip
    args = parser.parse_args(argv)
    config = GeneratorConfig(
        layout=args.layout,
        seed=args.seed,
        corrupt=args.corrupt,
        duration_s=args.duration,
        extrinsics_form=args.extrinsics,
        landmark_heights=args.landmark_heights,
        camera_offset_s=args.camera_offset,
        landmark_sensor_offset=args.landmark_sensor_offset,
    )
    try:
        path = generate(args.out, config)
    except (ValueError, FileExistsError) as exc:
        print(f"team_generator: error: {exc}", file=sys.stderr)
        return 2
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
