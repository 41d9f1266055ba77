"""The graphloc log format: one directory, a `manifest.json` and per-robot CSV tables
(documented in docs/log_format.md). Reader, writer and validation.

- `read_manifest(dir)` -> Manifest (robots, sensors with extrinsics, tables, landmarks).
- `iter_records(dir, tables=...)` streams typed records time-ordered across every robot and
  table (heapq.merge over per-file iterators); every row is validated and a bad row either
  raises ValueError naming file, line and field (on_error="raise") or is counted in a
  `SkipReport` (on_error="skip") -- nothing is dropped silently.
- `PlanarRun` is the numpy form of a planar multi-robot run (the MRCLAM loader's);
  `write_planar_run(run, dir)` writes it as a log. Logs are read into the one run type of the
  pipelines by `graphloc.datasets.graphloc_log.read_team_run` (`graphloc.datasets.open_run`).
"""

from __future__ import annotations

import csv
import heapq
import json
import math
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Iterator

import numpy as np


FORMAT = "graphloc-log"
VERSION = 2  # what the writers produce
VERSIONS = (1, 2)  # what the reader accepts (docs/log_format.md)
MANIFEST = "manifest.json"
LANDMARK_PREFIX = "landmark:"


# ---- skip accounting -------------------------------------------------------------------------
@dataclass
class SkipReport:
    """Counts of skipped input items by reason, plus the first `max_examples` messages
    (each naming file, line and field)."""

    counts: dict = field(default_factory=dict)
    examples: list = field(default_factory=list)
    max_examples: int = 20

    def add(self, reason: str, message: str, n: int = 1) -> None:
        self.counts[reason] = self.counts.get(reason, 0) + n
        if len(self.examples) < self.max_examples:
            self.examples.append(message)

    @property
    def total(self) -> int:
        return int(sum(self.counts.values()))

    def merge(self, other: "SkipReport") -> None:
        for reason, n in other.counts.items():
            self.counts[reason] = self.counts.get(reason, 0) + n
        self.examples.extend(other.examples[: max(0, self.max_examples - len(self.examples))])

    def as_dict(self) -> dict:
        return {
            "total": self.total,
            "counts": dict(sorted(self.counts.items())),
            "examples": list(self.examples),
        }


class _Sink:
    """Raise or count: the one place a bad row is handled."""

    def __init__(self, on_error: str, report: SkipReport | None):
        if on_error not in ("raise", "skip"):
            raise ValueError(f"on_error must be 'raise' or 'skip', got {on_error!r}")
        self.on_error = on_error
        self.report = report if report is not None else SkipReport()

    def bad(self, reason: str, message: str) -> None:
        if self.on_error == "raise":
            raise ValueError(message)
        self.report.add(reason, message)


# ---- records (one dataclass per table; CSV header = field names after time) -------------------
@dataclass(frozen=True)
class _Row:
    """What every record carries besides its columns: the file line it was read from."""

    line: int = field(default=0, kw_only=True, compare=False)


@dataclass(frozen=True)
class Odometry2D(_Row):
    """Unicycle velocity odometry: forward speed v [m/s], turn rate omega [rad/s]; holds until the
    next row."""

    time: float
    robot: str
    sensor: str
    v: float
    omega: float


@dataclass(frozen=True)
class RelativePose2D(_Row):
    """Odometry / scan-matching increment from time `time0` to `time` (frame at time0), with
    diagonal sigmas."""

    time: float
    robot: str
    sensor: str
    time0: float
    dx: float
    dy: float
    dtheta: float
    sigma_x: float
    sigma_y: float
    sigma_theta: float


@dataclass(frozen=True)
class RelativePose3D(_Row):
    """SE(3) increment from `time0` to `time` in the body frame at time0 (wheel / IMU odometry or
    scan matching): translation (tx, ty, tz), unit quaternion (qx, qy, qz, qw) as in TUM, and
    sigmas of GTSAM's Pose3 tangent (rotation rx, ry, rz [rad], translation tx, ty, tz [m])."""

    time: float
    robot: str
    sensor: str
    time0: float
    tx: float
    ty: float
    tz: float
    qx: float
    qy: float
    qz: float
    qw: float
    sigma_rx: float
    sigma_ry: float
    sigma_rz: float
    sigma_tx: float
    sigma_ty: float
    sigma_tz: float


@dataclass(frozen=True)
class Range(_Row):
    """Distance [m] from the sensor to `target` (a robot's body origin or 'landmark:<id>')."""

    time: float
    robot: str
    sensor: str
    target: str
    range: float


@dataclass(frozen=True)
class RangeBearing2D(_Row):
    """Range [m] and bearing [rad] in the sensor frame to `target` (a robot name or
    'landmark:<id>')."""

    time: float
    robot: str
    sensor: str
    target: str
    range: float
    bearing: float


@dataclass(frozen=True)
class Bearing3D(_Row):
    """Unit direction (x, y, z) in the sensor frame towards `target`."""

    time: float
    robot: str
    sensor: str
    target: str
    x: float
    y: float
    z: float


@dataclass(frozen=True)
class MarkerPixel(_Row):
    """Pixel (u, v) of marker `marker` on `target`, seen by camera `sensor`."""

    time: float
    robot: str
    sensor: str
    target: str
    marker: int
    u: float
    v: float


@dataclass(frozen=True)
class PoseCandidate(_Row):
    """Candidate k of a P3P (or other) hypothesis set: pose of `target` in the sensor frame
    (quaternion qw qx qy qz, translation tx ty tz) with a score >= 0. Rows sharing (time, sensor,
    target) form one set."""

    time: float
    robot: str
    sensor: str
    target: str
    k: int
    score: float
    qw: float
    qx: float
    qy: float
    qz: float
    tx: float
    ty: float
    tz: float


@dataclass(frozen=True)
class ScanRef(_Row):
    """A scan file (path relative to the log directory) captured by `sensor`."""

    time: float
    robot: str
    sensor: str
    path: str


@dataclass(frozen=True)
class GroundTruth2D(_Row):
    """Ground-truth planar pose."""

    time: float
    robot: str
    x: float
    y: float
    theta: float


TABLES: dict[str, type] = {
    "odometry": Odometry2D,
    "relative_pose": RelativePose2D,
    "relative_pose3": RelativePose3D,
    "range": Range,
    "range_bearing": RangeBearing2D,
    "bearing": Bearing3D,
    "markers": MarkerPixel,
    "candidates": PoseCandidate,
    "scans": ScanRef,
    "groundtruth": GroundTruth2D,
}
# sensor type each table's `sensor` column must have
SENSOR_TYPES = {
    "odometry": "odometry",
    "relative_pose": "odometry",
    "relative_pose3": "odometry",
    "range": "range",
    "range_bearing": "range_bearing",
    "bearing": "bearing",
    "markers": "camera",
    "candidates": "camera",
    "scans": "scanner",
}


def columns(table: str) -> list[str]:
    """CSV header of `table`: every record field except `robot` (the robot is the file's owner)."""
    return [f.name for f in fields(TABLES[table]) if f.name not in ("robot", "line")]


# ---- manifest --------------------------------------------------------------------------------
@dataclass(frozen=True)
class Sensor:
    """name, type (odometry | range_bearing | bearing | camera | scanner), extrinsics body_T_sensor
    as a 4x4 matrix, and free-form `params` (noise sigmas, intrinsics, ...)."""

    name: str
    type: str
    body_T_sensor: np.ndarray
    params: dict = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class Robot:
    name: str
    kind: str
    sensors: tuple[Sensor, ...]
    tables: dict = field(compare=False, default_factory=dict)  # table name -> relative csv path
    initial_pose: tuple | None = None  # (x, y, theta) or (x, y, z, qx, qy, qz, qw) if known
    meta: dict = field(default_factory=dict, compare=False)
    # version 2 (docs/log_format.md): state space, anchoring, surface, markers
    planar: bool = True  # moves in the floor plane (SE(2) motion embedded in SE(3))
    static: bool = False  # never moves: one pose for the whole run
    initial_sigma: tuple | None = (
        None  # (rotation [rad], translation [m]) of the initial-pose prior
    )
    surface: dict | None = None  # {"point": [..], "normal": [..]} plane the robot climbs on
    markers: tuple | None = None  # ((x, y, z), ...) marker layout in the body frame
    identical_markers: bool = False  # markers cannot be told apart (seed 001: 24 x 4 hypotheses)

    def sensor(self, name: str) -> Sensor | None:
        return next((s for s in self.sensors if s.name == name), None)


@dataclass(frozen=True)
class Manifest:
    root: Path
    name: str
    robots: tuple[Robot, ...]
    landmarks_file: str | None
    start_time: float | None = None
    meta: dict = field(default_factory=dict, compare=False)

    def robot(self, name: str) -> Robot | None:
        return next((r for r in self.robots if r.name == name), None)


def _extrinsics(value, where: str) -> np.ndarray:
    """[x, y, theta] (planar) or {"xyz": [...], "rpy": [...]} or a 4x4 list -> 4x4 matrix."""
    if value is None:
        return np.eye(4)
    T = np.eye(4)
    if isinstance(value, dict):
        xyz = np.asarray(value.get("xyz", [0, 0, 0]), dtype=float)
        rpy = np.asarray(value.get("rpy", [0, 0, 0]), dtype=float)
        if xyz.shape != (3,) or rpy.shape != (3,):
            raise ValueError(f"{where}: extrinsics xyz and rpy must have 3 numbers")
        from scipy.spatial.transform import Rotation

        T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
        T[:3, 3] = xyz
    else:
        arr = np.asarray(value, dtype=float)
        if arr.shape == (3,):
            c, s = math.cos(arr[2]), math.sin(arr[2])
            T[:2, :2] = [[c, -s], [s, c]]
            T[:2, 3] = arr[:2]
        elif arr.shape == (4, 4):
            T = arr
        else:
            raise ValueError(
                f"{where}: extrinsics must be [x, y, theta], {{xyz, rpy}} or 4x4, "
                f"got shape {arr.shape}"
            )
    if not np.isfinite(T).all():
        raise ValueError(f"{where}: extrinsics contain NaN/inf")
    return T


def read_manifest(root: str | Path) -> Manifest:
    root = Path(root)
    path = root / MANIFEST
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no log manifest (is {root} a graphloc log directory?)")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: line {exc.lineno}: invalid JSON ({exc.msg})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: the manifest must be a JSON object, got {type(data).__name__}")
    for key, kind in (("robots", list), ("landmarks", dict), ("meta", dict)):
        if data.get(key) is not None and not isinstance(data[key], kind):
            raise ValueError(
                f"{path}: field '{key}' must be a JSON {kind.__name__.replace('dict', 'object')}"
            )
    if data.get("format") != FORMAT:
        raise ValueError(f"{path}: field 'format' must be {FORMAT!r}, got {data.get('format')!r}")
    version = data.get("version")
    if version not in VERSIONS:
        raise ValueError(
            f"{path}: field 'version' {version!r} unsupported (this reader: {VERSIONS})"
        )
    robots = []
    for i, r in enumerate(data.get("robots") or []):
        where = f"{path}: robots[{i}]"
        if not isinstance(r, dict) or not r.get("name"):
            raise ValueError(f"{where}: field 'name' missing")
        sensors = []
        for j, s in enumerate(r.get("sensors") or []):
            if not isinstance(s, dict) or not s.get("name") or not s.get("type"):
                raise ValueError(f"{where}.sensors[{j}]: fields 'name' and 'type' required")
            sensors.append(
                Sensor(
                    s["name"],
                    s["type"],
                    _extrinsics(s.get("extrinsics"), f"{where}.sensors[{j}]"),
                    dict(s.get("params") or {}),
                )
            )
        tables = dict(r.get("tables") or {})
        for t in tables:
            if t not in TABLES:
                raise ValueError(
                    f"{where}: field 'tables' names unknown table {t!r}; known: {', '.join(TABLES)}"
                )
        if not isinstance(r.get("tables") or {}, dict):
            raise ValueError(f"{where}: field 'tables' must be a JSON object (table name -> path)")
        sizes = (3,) if version == 1 else (3, 7)
        init = _numbers(r.get("initial_pose"), sizes, f"{where}: field 'initial_pose'")
        if init is not None and len(init) == 7 and not 0.5 < math.hypot(*init[3:]) < 2.0:
            raise ValueError(
                f"{where}: field 'initial_pose': quaternion (qx, qy, qz, qw) is not unit"
            )
        kind = r.get("kind", "ground")
        extra = {}
        if version >= 2:
            extra["planar"] = _flag(r, "planar", kind == "ground", where)
            extra["static"] = _flag(r, "static", False, where)
            extra["identical_markers"] = _flag(r, "identical_markers", False, where)
            extra["initial_sigma"] = _numbers(
                r.get("initial_sigma"), (2,), f"{where}: field 'initial_sigma'", positive=True
            )
            surface = r.get("surface")
            if surface is not None:
                if not isinstance(surface, dict):
                    raise ValueError(
                        f'{where}: field \'surface\' must be {{"point": [x, y, z], "normal": [..]}}'
                    )
                for key in ("point", "normal"):
                    _numbers(
                        surface.get(key), (3,), f"{where}: field 'surface.{key}'", required=True
                    )
                if math.hypot(*surface["normal"]) < 1e-9:
                    raise ValueError(f"{where}: field 'surface.normal' must be non-zero")
                extra["surface"] = {
                    "point": [float(a) for a in surface["point"]],
                    "normal": [float(a) for a in surface["normal"]],
                }
            markers = r.get("markers")
            if markers is not None:
                if not isinstance(markers, list) or len(markers) < 3:
                    raise ValueError(
                        f"{where}: field 'markers' must list at least 3 points [x, y, z]"
                    )
                extra["markers"] = tuple(
                    _numbers(m, (3,), f"{where}: field 'markers[{j}]'", required=True)
                    for j, m in enumerate(markers)
                )
        robots.append(
            Robot(r["name"], kind, tuple(sensors), tables, init, dict(r.get("meta") or {}), **extra)
        )
    names = [r.name for r in robots]
    if not robots or len(set(names)) != len(names):
        raise ValueError(
            f"{path}: field 'robots' must list at least one robot with unique names, got {names}"
        )
    lm = (data.get("landmarks") or {}).get("file")
    start = data.get("start_time")
    if start is not None and not (isinstance(start, (int, float)) and math.isfinite(start)):
        raise ValueError(f"{path}: field 'start_time' must be a finite number, got {start!r}")
    return Manifest(
        root, data.get("name", root.name), tuple(robots), lm, start, dict(data.get("meta") or {})
    )


def _numbers(value, sizes: tuple, where: str, positive: bool = False, required: bool = False):
    """A JSON list of finite numbers of one of the lengths `sizes` -> tuple (None if absent)."""
    if value is None and not required:
        return None
    try:
        out = tuple(float(a) for a in value)
    except (TypeError, ValueError):
        out = ()
    if len(out) not in sizes or not all(math.isfinite(a) and abs(a) < 1e9 for a in out):
        raise ValueError(
            f"{where} must be {' or '.join(map(str, sizes))} finite numbers, got {value!r}"
        )
    if positive and not all(a > 0 for a in out):
        raise ValueError(f"{where} must be > 0, got {value!r}")
    return out


def _flag(robot: dict, name: str, default: bool, where: str) -> bool:
    value = robot.get(name, default)
    if not isinstance(value, bool):
        raise ValueError(f"{where}: field '{name}' must be true or false, got {value!r}")
    return value


def write_manifest(manifest_dict: dict, root: str | Path) -> Path:
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    body = {"format": FORMAT, "version": VERSION, **manifest_dict}
    (root / MANIFEST).write_text(json.dumps(body, indent=2) + "\n")
    return root / MANIFEST


# ---- streaming, validated reading ------------------------------------------------------------
def _converter(tp):
    if tp in (float, "float"):
        return float
    if tp in (int, "int"):
        return int
    return str


def iter_table(
    manifest: Manifest,
    robot: Robot,
    table: str,
    on_error: str = "raise",
    report: SkipReport | None = None,
    landmark_ids: set | None = None,
) -> Iterator:
    """Validated records of one robot's table, in file order. Checks: header, field count, number
    parsing, NaN/inf, time non-decreasing, known sensor (of the right type), known target."""
    sink = _Sink(on_error, report)
    cls = TABLES[table]
    cols = columns(table)
    convs = {f.name: _converter(f.type) for f in fields(cls)}
    path = manifest.root / robot.tables[table]
    robots = {r.name for r in manifest.robots}
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: table {table!r} of robot {robot.name!r} listed in manifest but missing"
        )
    last_time = -math.inf
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header is None or [h.strip() for h in header] != cols:
            raise ValueError(f"{path}: line 1: header must be {','.join(cols)}, got {header}")
        for row in reader:
            line = reader.line_num
            where = f"{path}: line {line}"
            if not row or (len(row) == 1 and not row[0].strip()) or row[0].lstrip().startswith("#"):
                continue
            if len(row) != len(cols):
                sink.bad("field_count", f"{where}: expected {len(cols)} fields, got {len(row)}")
                continue
            values = {}
            ok = True
            for name, text in zip(cols, row):
                conv = convs[name]
                try:
                    value = conv(text.strip())
                except ValueError:
                    sink.bad(
                        "parse",
                        f"{where}: field '{name}': cannot parse {text.strip()!r} "
                        f"as {conv.__name__}",
                    )
                    ok = False
                    break
                if conv is float and not math.isfinite(value):
                    sink.bad("non_finite", f"{where}: field '{name}': {text.strip()} is not finite")
                    ok = False
                    break
                values[name] = value
            if not ok:
                continue
            if values["time"] < last_time:
                sink.bad(
                    "time_backwards",
                    f"{where}: field 'time': {values['time']} goes backwards "
                    f"(previous {last_time})",
                )
                continue
            if "sensor" in values:
                sensor = robot.sensor(values["sensor"])
                if sensor is None:
                    sink.bad(
                        "unknown_sensor",
                        f"{where}: field 'sensor': robot {robot.name!r} "
                        f"has no sensor {values['sensor']!r}",
                    )
                    continue
                if sensor.type != SENSOR_TYPES[table]:
                    sink.bad(
                        "sensor_type",
                        f"{where}: field 'sensor': {values['sensor']!r} is a {sensor.type}, "
                        f"table {table} needs a {SENSOR_TYPES[table]}",
                    )
                    continue
            if "target" in values and not _known_target(values["target"], robots, landmark_ids):
                sink.bad(
                    "unknown_target",
                    f"{where}: field 'target': {values['target']!r} "
                    "is neither a robot nor a known landmark",
                )
                continue
            last_time = values["time"]
            yield cls(robot=robot.name, line=line, **values)


def _known_target(target: str, robots: set, landmark_ids: set | None) -> bool:
    if target in robots:
        return True
    if target.startswith(LANDMARK_PREFIX):
        try:
            lid = int(target[len(LANDMARK_PREFIX) :])
        except ValueError:
            return False
        return landmark_ids is None or lid in landmark_ids
    return False


def read_landmarks(manifest: Manifest) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ids (L,), positions (L,3), sigmas (L,3) from the landmark table (empty arrays if none)."""
    if manifest.landmarks_file is None:
        return np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 3))
    path = manifest.root / manifest.landmarks_file
    ids, xyz, sig = [], [], []
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        expect = ["id", "x", "y", "z", "sigma_x", "sigma_y", "sigma_z"]
        if header is None or [h.strip() for h in header] != expect:
            raise ValueError(f"{path}: line 1: header must be {','.join(expect)}, got {header}")
        for row in reader:
            where = f"{path}: line {reader.line_num}"
            if not row:
                continue
            if len(row) != 7:
                raise ValueError(f"{where}: expected 7 fields, got {len(row)}")
            try:
                lid = int(row[0])
            except ValueError:
                raise ValueError(f"{where}: field 'id': cannot parse {row[0]!r} as int") from None
            nums = []
            for name, text in zip(expect[1:], row[1:]):
                try:
                    val = float(text)
                except ValueError:
                    raise ValueError(f"{where}: field '{name}': cannot parse {text!r}") from None
                if not math.isfinite(val) or (name.startswith("sigma") and val < 0):
                    raise ValueError(
                        f"{where}: field '{name}': {text} must be finite (sigmas >= 0)"
                    )
                nums.append(val)
            if lid in ids:
                raise ValueError(f"{where}: field 'id': landmark {lid} listed twice")
            ids.append(lid)
            xyz.append(nums[:3])
            sig.append(nums[3:])
    return (
        np.array(ids, dtype=int),
        np.array(xyz, dtype=float).reshape(-1, 3),
        np.array(sig, dtype=float).reshape(-1, 3),
    )


def is_tum(path: str) -> bool:
    """3D ground truth is a TUM file (graphloc.datasets.graphloc_log.read_tum_poses), not a CSV
    table."""
    return str(path).endswith(".tum")


def iter_records(
    root: str | Path,
    tables=None,
    robots=None,
    on_error: str = "raise",
    report: SkipReport | None = None,
) -> Iterator:
    """All records of the log (optionally only `tables` / `robots`), merged in time order across
    robots and tables (heapq.merge; ties keep robot-then-table order). Streaming: one row per file
    in memory."""
    manifest = read_manifest(root)
    # without a landmarks file (SLAM: positions unknown) every landmark id is acceptable
    landmark_ids = (
        None if manifest.landmarks_file is None else set(read_landmarks(manifest)[0].tolist())
    )
    wanted_tables = list(TABLES) if tables is None else list(tables)
    for t in wanted_tables:
        if t not in TABLES:
            raise ValueError(f"unknown table {t!r}; known: {', '.join(TABLES)}")
    known = {r.name for r in manifest.robots}
    for name in robots or []:
        if name not in known:
            raise ValueError(
                f"{manifest.root / MANIFEST}: unknown robot {name!r}; robots: {sorted(known)}"
            )
    streams = [
        iter_table(manifest, r, t, on_error, report, landmark_ids)
        for r in manifest.robots
        if robots is None or r.name in robots
        for t in wanted_tables
        if t in r.tables and not is_tum(r.tables[t])
    ]
    return heapq.merge(*streams, key=lambda rec: rec.time)


# ---- planar multi-robot run (numpy form) -----------------------------------------------------
@dataclass(frozen=True)
class PlanarRun:
    """A planar multi-robot run in arrays (the MRCLAM loader's form;
    `graphloc.run.team_run_from_planar` turns it into the TeamRun every pipeline takes).

    robots: R names; initial_poses: (R,3) (x, y, theta) at start_time (NaN row = unknown);
    odometry[r]: (N_r,3) time, v, omega; groundtruth[r]: (G_r,4) time, x, y, theta or None;
    observations (M rows, time-sorted): obs_time, obs_robot (observer index), obs_target_robot
    (index or -1), obs_landmark (landmark id or -1), obs_range [m], obs_bearing [rad] (robot body
    frame);
    landmark_ids (L,), landmark_xy (L,2), landmark_sigma (L,2); skips: what the loader skipped.
    """

    name: str
    robots: tuple
    start_time: float
    initial_poses: np.ndarray
    odometry: tuple
    groundtruth: tuple
    obs_time: np.ndarray
    obs_robot: np.ndarray
    obs_target_robot: np.ndarray
    obs_landmark: np.ndarray
    obs_range: np.ndarray
    obs_bearing: np.ndarray
    landmark_ids: np.ndarray
    landmark_xy: np.ndarray
    landmark_sigma: np.ndarray
    skips: SkipReport = field(default_factory=SkipReport, compare=False)
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        R = len(self.robots)
        if (
            self.initial_poses.shape != (R, 3)
            or len(self.odometry) != R
            or len(self.groundtruth) != R
        ):
            raise ValueError(
                f"PlanarRun: initial_poses must be ({R},3) and odometry/groundtruth "
                f"have {R} entries"
            )
        m = self.obs_time.shape
        for name in ("obs_robot", "obs_target_robot", "obs_landmark", "obs_range", "obs_bearing"):
            if getattr(self, name).shape != m:
                raise ValueError(
                    f"PlanarRun: {name} must have shape {m}, got {getattr(self, name).shape}"
                )
        for r, od in enumerate(self.odometry):
            if od.ndim != 2 or od.shape[1] != 3:
                raise ValueError(
                    f"PlanarRun: odometry of {self.robots[r]} must be (N,3), got {od.shape}"
                )

    @property
    def end_time(self) -> float:
        return float(min(od[-1, 0] for od in self.odometry if len(od)))

    def duration(self) -> float:
        return self.end_time - self.start_time


def write_planar_run(run: PlanarRun, root: str | Path, sensor_sigmas=None) -> Path:
    """Write `run` as a graphloc log directory (manifest.json + robot tables + landmarks.csv)."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    robots = []
    for r, name in enumerate(run.robots):
        (root / name).mkdir(exist_ok=True)
        tables = {"odometry": f"{name}/odometry.csv", "range_bearing": f"{name}/range_bearing.csv"}
        od = run.odometry[r]
        _write_csv(
            root / tables["odometry"],
            columns("odometry"),
            [(f"{t:.6f}", "wheels", f"{v:.6g}", f"{w:.6g}") for t, v, w in od],
        )
        sel = np.flatnonzero(run.obs_robot == r)
        rows = []
        for i in sel:
            target = (
                run.robots[run.obs_target_robot[i]]
                if run.obs_target_robot[i] >= 0
                else f"{LANDMARK_PREFIX}{run.obs_landmark[i]}"
            )
            rows.append(
                (
                    f"{run.obs_time[i]:.6f}",
                    "camera",
                    target,
                    f"{run.obs_range[i]:.6g}",
                    f"{run.obs_bearing[i]:.6g}",
                )
            )
        _write_csv(root / tables["range_bearing"], columns("range_bearing"), rows)
        if run.groundtruth[r] is not None:
            tables["groundtruth"] = f"{name}/groundtruth.csv"
            _write_csv(
                root / tables["groundtruth"],
                columns("groundtruth"),
                [
                    (f"{t:.6f}", f"{x:.8g}", f"{y:.8g}", f"{th:.8g}")
                    for t, x, y, th in run.groundtruth[r]
                ],
            )
        init = run.initial_poses[r]
        robots.append(
            {
                "name": name,
                "kind": "ground",
                "initial_pose": None if not np.isfinite(init).all() else [float(a) for a in init],
                "sensors": [
                    {"name": "wheels", "type": "odometry"},
                    {
                        "name": "camera",
                        "type": "range_bearing",
                        "extrinsics": [0.0, 0.0, 0.0],
                        "params": dict(sensor_sigmas or {}),
                    },
                ],
                "tables": tables,
            }
        )
    _write_csv(
        root / "landmarks.csv",
        ["id", "x", "y", "z", "sigma_x", "sigma_y", "sigma_z"],
        [
            (int(i), f"{p[0]:.8g}", f"{p[1]:.8g}", "0", f"{s[0]:.3g}", f"{s[1]:.3g}", "0")
            for i, p, s in zip(run.landmark_ids, run.landmark_xy, run.landmark_sigma)
        ],
    )
    write_manifest(
        {
            "name": run.name,
            "start_time": run.start_time,
            "robots": robots,
            "landmarks": {"file": "landmarks.csv"},
            "meta": run.meta,
        },
        root,
    )
    return root


def write_table(path: str | Path, table: str, rows) -> Path:
    """One table of a log: header `columns(table)`, then `rows` (floats written losslessly, so
    large time stamps keep their digits); parent folders created."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_csv(path, columns(table), rows)
    return path


def _write_csv(path: Path, header: list[str], rows) -> None:
    def text(v):
        return repr(float(v)) if isinstance(v, (float, np.floating)) else str(v)

    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows([text(v) for v in row] for row in rows)
