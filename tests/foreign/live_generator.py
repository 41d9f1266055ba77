"""Team logs for the live API, written from docs/log_format.md alone (not `graphloc simulate`,
not `team_generator.py`'s geometry): 1-6 wheel-odometry robots with initial poses, each driving
its own smooth commands, with range, bearing and range-bearing rows to other robots and to
landmarks at irregular times, through sensors with extrinsics.

Geometries (`Scenario.geometry`):
- "corridor": robots in file down a 3 m wide, 60 m long corridor, posts on both walls;
- "loop": robots spread round a 15 m circle, driving it; landmarks inside and outside;
- "far": two groups 400 m apart, far from the origin (x ~ 5000 m), each with its own posts;
- "slope": a ceiling robot climbing a sloped ceiling (a surface, odometry in its plane) over
  ground robots, which range to it; it sees them and the posts through a down-looking camera.

Truth: each robot's pose at any time, the commands held between odometry rows (zero-order
hold, the docs' "held until the next row") integrated exactly from its true initial pose at
`start_time`. Odometry rows are the true commands plus white noise of the sensor's stated
densities (a sample held dt seconds carries density / sqrt(dt)); measurements are the true
geometry through the sensor's extrinsics plus noise of its stated sigmas; the manifest's
initial poses are the truth drawn from their stated `initial_sigma`. So the estimates should
sit within their covariances of the truth.

`generate(scenario)` -> `TeamLog` (rows in the log's time order, truth); `write_log(log, dir)`
writes the log directory."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# a robot's tables in the order docs/log_format.md lists them (the order rows of equal time
# are merged in by `graphloc online`: robot, then table)
TABLE_ORDER = ("odometry", "range", "range_bearing", "bearing")
COLUMNS = {
    "odometry": ("time", "sensor", "v", "omega"),
    "range": ("time", "sensor", "target", "range"),
    "range_bearing": ("time", "sensor", "target", "range", "bearing"),
    "bearing": ("time", "sensor", "target", "x", "y", "z"),
}


@dataclass(frozen=True)
class Scenario:
    geometry: str = "loop"  # corridor, loop, far, slope
    robots: int = 3  # 1-6 (slope: the ceiling robot is one of them)
    duration: float = 20.0  # [s] of driving after start_time
    start_time: float = 1000.0
    odometry_hz: tuple = (10.0, 20.0, 50.0, 100.0, 25.0, 40.0)  # per robot (cycled)
    measurement_hz: float = 2.0  # mean rate of each measuring sensor (exponential gaps)
    slam: bool = False  # no landmarks file: the landmarks are estimated
    density_v: float = 0.02  # odometry noise [m/sqrt(s)]
    density_w: float = 0.03  # [rad/sqrt(s)]
    range_sigma: float = 0.05
    range_sigma_per_m: float = 0.01
    bearing_sigma: float = 0.01
    initial_sigma: tuple = (0.01, 0.05)  # [rad, m]
    max_range: float = 15.0
    shared_times: bool = True  # some measurements of different robots at one time
    seed: int = 0


@dataclass
class RobotTruth:
    name: str
    kind: str
    origin: np.ndarray  # 4x4 world_T_body at start_time (the true initial pose)
    times: np.ndarray  # odometry row times
    v: np.ndarray  # true commands
    w: np.ndarray
    sensors: dict  # name -> (type, 4x4 body_T_sensor, manifest entry)
    surface: dict | None = None
    planar: bool = True
    initial_pose: list = field(default_factory=list)  # what the manifest states

    def planar_at(self, t: float) -> tuple:
        """(x, y, theta) of the body in its start frame at time t (exact zero-order hold): the
        state at the last row time at or after the start before t, carried on to t."""
        if self._states is None:  # the state at each row time from the start on
            self._states = {}
            state, cur = (0.0, 0.0, 0.0), self._start
            for i, ti in enumerate(self.times):
                if ti < self._start:
                    continue
                state = _carry(state, self.times, self.v, self.w, cur, ti)
                self._states[i] = state
                cur = ti
        i = int(np.searchsorted(self.times, t, "right")) - 1
        while i >= 0 and i not in self._states:
            i = -1 if self.times[i] < self._start else i - 1
        if i < 0:
            return _integrate(self.times, self.v, self.w, self._start, t)
        return _carry(self._states[i], self.times, self.v, self.w, self.times[i], t)

    def pose(self, t: float) -> np.ndarray:
        """4x4 world_T_body at time t."""
        return self.origin @ _planar_matrix(*self.planar_at(t))

    _start: float = 0.0
    _states: dict | None = None


@dataclass
class TeamLog:
    scenario: Scenario
    robots: list  # RobotTruth
    landmarks: dict  # id -> xyz
    landmark_sigma: dict  # id -> stated sigma [m]
    rows: list  # (time, robot index, table index, seq, robot, table, row dict), in log order
    manifest: dict

    @property
    def names(self) -> list[str]:
        return [r.name for r in self.robots]

    def pushes(self) -> list:
        """(robot, table, row) in time order, ties robot then table (the log's merge)."""
        return [(robot, table, dict(row)) for *_, robot, table, row in self.rows]


def _integrate(times, v, w, t0: float, t: float) -> tuple:
    """Unicycle from (0,0,0) at t0 to t under the held commands (zero before the first row)."""
    x = y = th = 0.0
    if t <= t0:
        return 0.0, 0.0, 0.0
    # breakpoints within (t0, t)
    i0 = int(np.searchsorted(times, t0, "right")) - 1
    cur = t0
    i = i0
    while cur < t:
        nxt = times[i + 1] if i + 1 < len(times) else math.inf
        end = min(nxt, t)
        dt = end - cur
        vv, ww = (v[i], w[i]) if i >= 0 else (0.0, 0.0)
        x, y, th = _arc(x, y, th, vv * dt, ww * dt)
        cur = end
        i += 1
    return x, y, th


def _carry(state, times, v, w, t0: float, t: float) -> tuple:
    """`state` at t0 carried to t >= t0 under the held commands."""
    dx, dy, dth = _integrate(times, v, w, t0, t)
    x, y, th = state
    c, s = math.cos(th), math.sin(th)
    return x + c * dx - s * dy, y + s * dx + c * dy, th + dth


def _arc(x, y, th, ds, dth):
    chord = ds * np.sinc(dth / 2 / np.pi)
    mid = th + dth / 2
    return x + chord * math.cos(mid), y + chord * math.sin(mid), th + dth


def _planar_matrix(x, y, th) -> np.ndarray:
    c, s = math.cos(th), math.sin(th)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:2, 3] = [x, y]
    return m


def _rpy_matrix(rpy) -> np.ndarray:
    r, p, y = rpy
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _transform(xyz, rot) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = xyz
    return m


def _quaternion(rot) -> list:
    """x, y, z, w of a rotation matrix."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(rot).as_quat().tolist()


def _exp_so3(w) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(w).as_matrix()


def _ground_sensors(rng, r: int) -> dict:
    """A ground robot's sensors: wheels, a UWB-like range sensor on a mast, a planar
    range-bearing scanner off-centre (its height 0: the targets in its plane), a tilted camera
    giving bearings; extrinsics in the three forms the docs allow."""
    mast = [float(rng.uniform(-0.1, 0.1)), float(rng.uniform(-0.1, 0.1)), 0.35]
    scan = [0.2, float(rng.uniform(-0.05, 0.05)), float(rng.uniform(-0.3, 0.3))]
    cam_rpy = [-math.pi / 2 + 0.05, 0.0, -math.pi / 2 + float(rng.uniform(-0.2, 0.2))]
    cam_xyz = [0.15, 0.0, 0.25]
    ex_mat = _transform(mast, np.eye(3))
    return {
        "wheels": ("odometry", np.eye(4), {"name": "wheels", "type": "odometry"}),
        "uwb": (
            "range",
            ex_mat,
            {"name": "uwb", "type": "range", "extrinsics": ex_mat.tolist()},
        ),
        "scanner": (
            "range_bearing",
            _planar_matrix(*scan),
            {"name": "scanner", "type": "range_bearing", "extrinsics": scan},
        ),
        "cam": (
            "bearing",
            _transform(cam_xyz, _rpy_matrix(cam_rpy)),
            {"name": "cam", "type": "bearing", "extrinsics": {"xyz": cam_xyz, "rpy": cam_rpy}},
        ),
    }


def _ceiling_sensors() -> dict:
    """A ceiling climber: wheels and a camera looking 'up' along its body z (into the room,
    away from the ceiling): the docs' down-looking camera, rpy [pi, 0, 0] from a z-down body is
    the identity here since the body's z already points into the room."""
    cam_xyz = [0.05, 0.0, 0.05]
    cam_rpy = [0.0, 0.0, 0.3]
    return {
        "wheels": ("odometry", np.eye(4), {"name": "wheels", "type": "odometry"}),
        "cam": (
            "bearing",
            _transform(cam_xyz, _rpy_matrix(cam_rpy)),
            {"name": "cam", "type": "bearing", "extrinsics": {"xyz": cam_xyz, "rpy": cam_rpy}},
        ),
    }


def _commands(rng, times, speed: float, turn: float, phase: float):
    """Smooth commands: a speed around `speed`, a turn rate around `turn` with a slow wiggle."""
    t = times - times[0]
    v = speed * (1.0 + 0.2 * np.sin(0.3 * t + phase))
    w = turn + 0.15 * np.sin(0.5 * t + 2 * phase) + 0.05 * np.sin(1.7 * t + phase)
    return v, w


def _layout(sc: Scenario, rng):
    """(per robot: origin 4x4, speed, turn, kind, surface), landmarks id -> xyz."""
    n = sc.robots
    robots, landmarks = [], {}
    lid = 10
    if sc.geometry == "corridor":
        for r in range(n):
            origin = _transform([-2.5 * r, 0.6 * (-1) ** r, 0.0], _rpy_matrix([0, 0, 0.02 * r]))
            robots.append((origin, 0.45, 0.0, "ground", None))
        for x in np.arange(-15.0, 25.0, 3.0):
            for y in (-1.5, 1.5):
                landmarks[lid] = [
                    float(x + rng.uniform(-0.3, 0.3)),
                    y,
                    float(rng.choice([0.0, 1.2])),
                ]
                lid += 1
    elif sc.geometry == "loop":
        radius = 15.0
        for r in range(n):
            a = 2 * math.pi * r / n
            origin = _transform(
                [radius * math.cos(a), radius * math.sin(a), 0.0],
                _rpy_matrix([0, 0, a + math.pi / 2]),
            )
            robots.append((origin, 0.4, 0.4 / radius, "ground", None))
        for k in range(16):
            a = 2 * math.pi * k / 16 + 0.1
            rr = radius + (3.0 if k % 2 else -3.0)
            landmarks[lid] = [rr * math.cos(a), rr * math.sin(a), 0.0 if k % 3 else 0.8]
            lid += 1
    elif sc.geometry == "far":
        centres = [np.array([5000.0, -3000.0]), np.array([5400.0, -3000.0])]
        for r in range(n):
            c = centres[r % 2]
            origin = _transform(
                [c[0] + 1.5 * (r // 2), c[1] + 2.0 * (r // 2), 0.0], _rpy_matrix([0, 0, 1.0 + r])
            )
            robots.append((origin, 0.35, 0.12, "ground", None))
        for c in centres:
            for k in range(8):
                a = 2 * math.pi * k / 8
                landmarks[lid] = [float(c[0] + 6 * math.cos(a)), float(c[1] + 6 * math.sin(a)), 0.0]
                lid += 1
    elif sc.geometry == "slope":
        # ceiling through (0, 0, 4) rising along x: normal (pointing into the room) tilted
        normal = np.array([0.25, 0.0, -1.0])
        normal /= np.linalg.norm(normal)
        # body z along the normal, body x up the slope
        z = normal
        x = np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        rot = np.column_stack([x, y, z])
        point = np.array([0.0, 0.0, 4.0])
        robots.append(
            (
                _transform(point + 0.5 * y, rot),
                0.25,
                0.1,
                "ceiling",
                {"point": point.tolist(), "normal": normal.tolist()},
            )
        )
        for r in range(1, n):
            a = 2 * math.pi * r / max(n - 1, 1)
            origin = _transform(
                [3 * math.cos(a), 3 * math.sin(a), 0.0], _rpy_matrix([0, 0, a + 1.6])
            )
            robots.append((origin, 0.3, 0.1, "ground", None))
        for k in range(10):
            a = 2 * math.pi * k / 10
            landmarks[lid] = [6 * math.cos(a), 6 * math.sin(a), 0.0 if k % 2 else 1.0]
            lid += 1
    else:
        raise ValueError(f"unknown geometry {sc.geometry!r}")
    return robots, landmarks


def generate(sc: Scenario) -> TeamLog:
    if not 1 <= sc.robots <= 6:
        raise ValueError("1-6 robots")
    rng = np.random.default_rng(sc.seed)
    layout, landmarks = _layout(sc, rng)
    t0, t1 = sc.start_time, sc.start_time + sc.duration
    robots: list[RobotTruth] = []
    for r, (origin, speed, turn, kind, surface) in enumerate(layout):
        hz = sc.odometry_hz[r % len(sc.odometry_hz)]
        # rows from a little before the start (a logger already running) to the end; the
        # robots whose rates divide each other share row times (equal timestamps)
        k0 = -int(rng.integers(0, 5))
        times = t0 + np.arange(k0, int(round(sc.duration * hz)) + 1) / hz
        v, w = _commands(rng, times, speed, turn, float(rng.uniform(0, 6)))
        name = f"{'climber' if kind == 'ceiling' else 'rover'}{r}" if r != 1 else "Unit-B.2"
        sensors = _ceiling_sensors() if kind == "ceiling" else _ground_sensors(rng, r)
        truth = RobotTruth(name, kind, origin, times, v, w, sensors, surface, kind != "ceiling")
        truth._start = t0
        # the manifest's initial pose: the truth drawn from the stated sigmas
        rs, ts = sc.initial_sigma
        noisy = origin.copy()
        if kind == "ceiling":
            noisy[:3, :3] = origin[:3, :3] @ _exp_so3(rng.normal(0, rs, 3))
            noisy[:3, 3] += rng.normal(0, ts, 3)
            truth.initial_pose = [*noisy[:3, 3].tolist(), *_quaternion(noisy[:3, :3])]
        else:
            th = math.atan2(origin[1, 0], origin[0, 0]) + rng.normal(0, rs)
            xy = origin[:2, 3] + rng.normal(0, ts, 2)
            truth.initial_pose = [float(xy[0]), float(xy[1]), float(th)]
        robots.append(truth)

    rows = []
    seq = 0

    def add(t, r, table, row):
        nonlocal seq
        rows.append((float(t), r, TABLE_ORDER.index(table), seq, robots[r].name, table, row))
        seq += 1

    for r, rb in enumerate(robots):
        dt = np.diff(rb.times, append=rb.times[-1] + np.diff(rb.times[-2:]))
        nv = rng.normal(0, 1, len(dt)) * sc.density_v / np.sqrt(dt)
        nw = rng.normal(0, 1, len(dt)) * sc.density_w / np.sqrt(dt)
        for t, v, w, a, b in zip(rb.times, rb.v, rb.w, nv, nw):
            add(
                t,
                r,
                "odometry",
                {"time": float(t), "sensor": "wheels", "v": float(v + a), "omega": float(w + b)},
            )

    # measurement times: per (robot, sensor) exponential gaps; with shared_times, a set of
    # common instants that every robot measures at
    common = t0 + np.sort(rng.uniform(0.2, sc.duration - 0.2, 6)) if sc.shared_times else []
    for r, rb in enumerate(robots):
        for sname, (stype, ext, _) in rb.sensors.items():
            if stype == "odometry":
                continue
            t, times = t0 + rng.exponential(1 / sc.measurement_hz), []
            while t < t1 - 0.1:
                times.append(t)
                t += rng.exponential(1 / sc.measurement_hz)
            times = np.sort(np.concatenate([times, common]))
            for t in times:
                for target, p_world in _targets(robots, landmarks, r, t):
                    row = _measure(sc, rng, rb, sname, stype, ext, float(t), target, p_world)
                    if row is not None:
                        add(t, r, stype, row)
    rows.sort(key=lambda e: e[:4])
    sigma = {i: float(rng.choice([0.0, 0.02, 0.05])) for i in landmarks}
    log = TeamLog(
        sc, robots, {i: np.asarray(p, float) for i, p in landmarks.items()}, sigma, rows, {}
    )
    log.manifest = _manifest(log)
    return log


def _targets(robots, landmarks, r, t):
    for q, other in enumerate(robots):
        if q != r:
            yield other.name, other.pose(t)[:3, 3]
    for i, p in landmarks.items():
        yield f"landmark:{i}", np.asarray(p, float)


def _measure(sc, rng, rb, sname, stype, ext, t, target, p_world):
    world_T_sensor = rb.pose(t) @ ext
    p = np.linalg.inv(world_T_sensor) @ np.r_[p_world, 1.0]
    p = p[:3]
    dist = float(np.linalg.norm(p))
    if dist > sc.max_range or dist < 0.5:
        return None
    if stype == "range":
        sigma = math.hypot(sc.range_sigma, sc.range_sigma_per_m * dist)
        value = dist + rng.normal(0, sigma)
        if value <= 0:
            return None
        return {"time": t, "sensor": sname, "target": target, "range": float(value)}
    if stype == "range_bearing":
        if abs(p[2]) > 1e-6:  # planar: only targets in the scanner's plane
            return None
        sigma = math.hypot(sc.range_sigma, sc.range_sigma_per_m * dist)
        ang = math.atan2(p[1], p[0]) + rng.normal(0, sc.bearing_sigma)
        return {
            "time": t,
            "sensor": sname,
            "target": target,
            "range": float(dist + rng.normal(0, sigma)),
            "bearing": float(math.atan2(math.sin(ang), math.cos(ang))),
        }
    # bearing: a unit vector, the camera sees only what is in front of it (z > 0)
    if p[2] <= 0.1 * dist:
        return None
    d = p / dist
    e1 = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    d = d + sc.bearing_sigma * (rng.normal() * e1 + rng.normal() * e2)
    d /= np.linalg.norm(d)
    return {
        "time": t,
        "sensor": sname,
        "target": target,
        "x": float(d[0]),
        "y": float(d[1]),
        "z": float(d[2]),
    }


def _manifest(log: TeamLog) -> dict:
    sc = log.scenario
    robots = []
    for rb in log.robots:
        sensors = []
        for _, (stype, _, entry) in rb.sensors.items():
            entry = dict(entry)
            if stype == "odometry":
                entry["params"] = {"density_v": sc.density_v, "density_w": sc.density_w}
            elif stype == "bearing":
                entry["params"] = {"bearing_sigma": sc.bearing_sigma}
            else:
                entry["params"] = {
                    "range_sigma": sc.range_sigma,
                    "range_sigma_per_m": sc.range_sigma_per_m,
                    **({"bearing_sigma": sc.bearing_sigma} if stype == "range_bearing" else {}),
                }
            sensors.append(entry)
        tables = {
            t: f"{rb.name}/{t}.csv"
            for t in TABLE_ORDER
            if any(row[4] == rb.name and row[5] == t for row in log.rows)
        }
        entry = {
            "name": rb.name,
            "kind": rb.kind,
            "initial_pose": rb.initial_pose,
            "initial_sigma": list(sc.initial_sigma),
            "sensors": sensors,
            "tables": tables,
        }
        if not rb.planar:
            entry["planar"] = False
        if rb.surface is not None:
            entry["surface"] = rb.surface
        robots.append(entry)
    out = {
        "format": "graphloc-log",
        "version": 2,
        "name": f"live-{sc.geometry}-{sc.seed}",
        "start_time": sc.start_time,
        "robots": robots,
        "meta": {"generator": "tests/foreign/live_generator.py", "scenario": sc.geometry},
    }
    if not sc.slam:
        out["landmarks"] = {"file": "landmarks.csv"}
    return out


def write_log(log: TeamLog, root: Path, manifest: dict | None = None) -> Path:
    """The log directory of docs/log_format.md (floats written exactly: repr)."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    manifest = log.manifest if manifest is None else manifest
    (root / "manifest.json").write_text(json.dumps(manifest, indent=1))
    if "landmarks" in manifest:
        lines = ["id,x,y,z,sigma_x,sigma_y,sigma_z"]
        for i, p in log.landmarks.items():
            s = log.landmark_sigma[i]
            lines.append(",".join([str(i), *(repr(float(v)) for v in (*p, s, s, s))]))
        (root / "landmarks.csv").write_text("\n".join(lines) + "\n")
    files: dict = {}
    for *_, robot, table, row in log.rows:
        files.setdefault((robot, table), []).append(
            ",".join(
                repr(row[c]) if isinstance(row[c], float) else str(row[c]) for c in COLUMNS[table]
            )
        )
    for (robot, table), lines in files.items():
        path = root / robot / f"{table}.csv"
        path.parent.mkdir(exist_ok=True)
        path.write_text(",".join(COLUMNS[table]) + "\n" + "\n".join(lines) + "\n")
    return root
