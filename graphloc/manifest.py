"""The manifest of a graphloc log (`manifest.json`, docs/log_format.md): `read_manifest` checks
every field, names manifest and field in its errors and confines every path to the run."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.names import check_name, safe_name
from graphloc.records import MAX_COORDINATE, MAX_SIGMA, MAX_TIME, TABLES
from graphloc.structured import dumps_json, finite_number, read_json
from graphloc.textio import check_file, confined

FORMAT = "graphloc-log"
VERSION = 2  # what the writers produce
VERSIONS = (1, 2)  # what the reader accepts (docs/log_format.md)
MANIFEST = "manifest.json"


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
    base_radius: float | None = None  # [m] circular base seen as an ellipse (seed 003)

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


def _extrinsic_numbers(value, shape: tuple, where: str, field: str) -> np.ndarray:
    """A nested JSON list of finite numbers (not booleans) of `shape` -> array; ValueError
    naming `where` and the field otherwise."""
    arr = np.asarray(value, dtype=object)
    flat = arr.reshape(-1).tolist() if arr.shape == shape else None
    if flat is None or not all(finite_number(a) for a in flat):
        raise ValueError(
            f"{where}: extrinsics must be numbers: field '{field}' must be "
            f"{' x '.join(map(str, shape))} finite numbers, got {value!r}"
        )
    return np.array(flat, dtype=float).reshape(shape)


def _extrinsics(value, where: str) -> np.ndarray:
    """[x, y, theta] (planar) or {"xyz": [...], "rpy": [...]} or a 4x4 list -> 4x4 matrix
    (ValueError naming `where` and the field -- xyz, rpy, theta, matrix -- unless finite,
    plausible and a rigid transform)."""
    if value is None:
        return np.eye(4)
    T = np.eye(4)
    if isinstance(value, dict):
        unknown = sorted(set(value) - {"xyz", "rpy"})
        if unknown:
            raise ValueError(f"{where}: extrinsics has unknown field(s) {unknown}; use xyz, rpy")
        xyz = _extrinsic_numbers(value.get("xyz", [0, 0, 0]), (3,), where, "xyz")
        rpy = _extrinsic_numbers(value.get("rpy", [0, 0, 0]), (3,), where, "rpy")
        if np.abs(rpy).max() > 2 * np.pi:
            raise ValueError(
                f"{where}: extrinsics field 'rpy' must be angles in radians within +-2 pi (roll, "
                f"pitch, yaw about the body's x, y, z axes), got {rpy.tolist()}: degrees?"
            )
        T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
        T[:3, 3] = xyz
        if np.abs(xyz).max() > MAX_COORDINATE:
            raise ValueError(
                f"{where}: extrinsics field 'xyz' must lie within +-{MAX_COORDINATE:g} m"
            )
    try:
        if not isinstance(value, dict):
            shape = np.shape(np.asarray(value, dtype=object))
            if shape == (3,):
                arr = _extrinsic_numbers(value, (3,), where, "x, y, theta")
            elif shape == (4, 4):
                arr = _extrinsic_numbers(value, (4, 4), where, "matrix")
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
    except (TypeError, ValueError) as exc:
        if str(exc).startswith(where):
            raise
        raise ValueError(f"{where}: extrinsics must be numbers ({exc})") from None
    if not np.isfinite(T).all() or np.abs(T[:3, 3]).max() > MAX_COORDINATE:
        raise ValueError(
            f"{where}: extrinsics must be finite with translations within +-{MAX_COORDINATE:g} m"
        )
    R = T[:3, :3]
    if not (np.allclose(R @ R.T, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0):
        raise ValueError(f"{where}: extrinsics rotation is not a rotation matrix")
    if not np.allclose(T[3], [0, 0, 0, 1]):
        raise ValueError(f"{where}: extrinsics last row must be [0, 0, 0, 1]")
    return T


# sensor params that are noise: name -> (count, smallest allowed); every value <= MAX_SIGMA
NOISE_PARAMS = {
    "bearing_sigma": (1, "positive"),  # rad
    "range_sigma": (1, "positive"),  # m
    "range_sigma_per_m": (1, "non-negative"),  # m per m
    "pixel_sigma": (1, "positive"),  # px
    "candidate_sigmas": (2, "positive"),  # rad, m
    "icp_sigmas": (2, "positive"),  # rad, m
}


def check_noise_params(params: dict, where: str) -> None:
    """ValueError naming `where` and the field unless every noise param in `params` (see
    NOISE_PARAMS) is a plausible standard deviation: finite, > 0 (>= 0 for the per-metre growth)
    and at most MAX_SIGMA, so that no covariance built from it is NaN/inf or singular."""
    for name, (count, kind) in NOISE_PARAMS.items():
        value = params.get(name)
        if value is None:
            continue
        items = value if count > 1 else [value]
        try:
            ok = isinstance(items, (list, tuple)) and len(items) == count
            nums = [float(a) for a in items if not isinstance(a, (bool, str))] if ok else []
        except (TypeError, ValueError):
            nums = []
        low_ok = all(a > 0 if kind == "positive" else a >= 0 for a in nums)
        if len(nums) != count or not low_ok or not all(a <= MAX_SIGMA for a in nums):
            what = "a number" if count == 1 else f"a list of {count} numbers"
            raise ValueError(
                f"{where} '{name}' must be {what}, {kind} and at most {MAX_SIGMA:g}, got {value!r}"
            )


def read_manifest(root: str | Path) -> Manifest:
    root = Path(root)
    path = root / MANIFEST
    if not check_file(path, required=False):
        raise FileNotFoundError(f"{path}: no log manifest (is {root} a graphloc log directory?)")
    data = read_json(path, what="log manifest")
    if not isinstance(data, dict):
        raise ValueError(f"{path}: the manifest must be a JSON object, got {type(data).__name__}")
    _check_kinds(data, path, (("robots", list), ("landmarks", dict), ("meta", dict)))
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
        if not isinstance(r, dict):
            raise ValueError(f"{where}: must be a JSON object")
        check_name(r.get("name"), f"{where}: field 'name'")
        if not isinstance(r.get("kind", "ground"), str):
            raise ValueError(f"{where}: field 'kind' must be a string")
        _check_kinds(r, where, (("sensors", list), ("meta", dict)))
        sensors = []
        for j, s in enumerate(r.get("sensors") or []):
            if not isinstance(s, dict):
                raise ValueError(
                    f"{where}.sensors[{j}]: fields 'name' and 'type' must be given in a JSON "
                    f"object, got {s!r}"
                )
            check_name(s.get("name"), f"{where}.sensors[{j}]: field 'name'")
            if not _name(s.get("type")):
                raise ValueError(f"{where}.sensors[{j}]: field 'type' must be a non-empty string")
            if not isinstance(s.get("params") or {}, dict):
                raise ValueError(f"{where}.sensors[{j}]: field 'params' must be a JSON object")
            check_noise_params(s.get("params") or {}, f"{where}.sensors[{j}]: params field")
            sensors.append(
                Sensor(
                    s["name"],
                    s["type"],
                    _extrinsics(s.get("extrinsics"), f"{where}.sensors[{j}]"),
                    dict(s.get("params") or {}),
                )
            )
        if not isinstance(r.get("tables") or {}, dict):
            raise ValueError(f"{where}: field 'tables' must be a JSON object (table name -> path)")
        tables = dict(r.get("tables") or {})
        for t, rel in tables.items():
            if t not in TABLES:
                raise ValueError(
                    f"{where}: field 'tables' names unknown table {t!r}; known: {', '.join(TABLES)}"
                )
            confined(root, rel, f"{where}: field 'tables.{t}'")
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
                for key in ("distance_sigma", "attitude_sigma"):  # distance_sigma 0: none
                    if surface.get(key) is not None:
                        value = _numbers([surface[key]], (1,), f"{where}: field 'surface.{key}'")[0]
                        if not (value > 0 or (value == 0 and key == "distance_sigma")):
                            raise ValueError(
                                f"{where}: field 'surface.{key}' must be > 0, got {value}"
                            )
                        extra["surface"][key] = value
                if surface.get("body_axis") is not None:
                    axis = _numbers(
                        surface["body_axis"], (3,), f"{where}: field 'surface.body_axis'"
                    )
                    if math.hypot(*axis) < 1e-9:
                        raise ValueError(f"{where}: field 'surface.body_axis' must be non-zero")
                    extra["surface"]["body_axis"] = list(axis)
            if r.get("base_radius") is not None:
                extra["base_radius"] = _numbers(
                    [r["base_radius"]], (1,), f"{where}: field 'base_radius'", positive=True
                )[0]
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
    for i, r in enumerate(robots):
        sensor_names = [s.name for s in r.sensors]
        if len(set(sensor_names)) != len(sensor_names):
            raise ValueError(f"{path}: robots[{i}]: sensor names must be unique: {sensor_names}")
    if not robots or len(set(names)) != len(names):
        raise ValueError(
            f"{path}: field 'robots' must list at least one robot with unique names, got {names}"
        )
    lm = (data.get("landmarks") or {}).get("file")
    name = data["name"] if "name" in data else safe_name(root.resolve().name)
    check_name(name, f"{path}: field 'name'")
    if lm is not None:
        confined(root, lm, f"{path}: field 'landmarks.file'")
    start = data.get("start_time")
    if start is not None and not (
        isinstance(start, (int, float)) and not isinstance(start, bool) and abs(start) <= MAX_TIME
    ):
        raise ValueError(
            f"{path}: field 'start_time' must be a number within +-{MAX_TIME:g} s, got {start!r}"
        )
    return Manifest(root, name, tuple(robots), lm, start, dict(data.get("meta") or {}))


def _check_kinds(data: dict, where, kinds) -> None:
    """ValueError naming `where` and the field unless each (field, type) given is of its type."""
    for key, kind in kinds:
        if data.get(key) is not None and not isinstance(data[key], kind):
            raise ValueError(
                f"{where}: field '{key}' must be a JSON {kind.__name__.replace('dict', 'object')}"
            )


def _name(value) -> bool:
    """A usable name: a non-empty string without line breaks or NUL."""
    return isinstance(value, str) and bool(value.strip()) and not set(value) & {"\n", "\r", "\0"}


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
    (root / MANIFEST).write_text(dumps_json(body, indent=2) + "\n")
    return root / MANIFEST
