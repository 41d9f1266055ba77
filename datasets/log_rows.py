"""Parsing of a graphloc log directory (docs/log_format.md) into typed tables, `LogRows`: each
row through its table kind's handler (`TABLE_HANDLERS`) -> a typed row, or a `Skip` naming
file, line and field; no front-end work."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, NamedTuple

import gtsam
import numpy as np

from graphloc.datasets.camera_tables import positive_param
from graphloc.datasets.log_observations import marker_columns
from graphloc.factors.surface import SurfacePlane
from graphloc.manifest import Manifest, read_manifest
from graphloc.textio import SkipReport, Sink
from graphloc.io import is_tum, iter_records, read_landmarks
from graphloc.records import LANDMARK_PREFIX, MAX_COORDINATE, MAX_TIME, TABLES
from graphloc.run import (
    NOISE_DEFAULTS,
    Motion,
    PointMeasurement,
    TeamRobot,
    planar_covariance,
    pose_from_planar,
    pose_from_xyz_quat,
)
from graphloc.textio import check_file, shown, text_lines

TABLE_OF = {cls: name for name, cls in TABLES.items()}  # record class -> its table's name


class Skip(NamedTuple):
    """A row a handler refuses: counted under `reason` (or raised, `on_error="raise"`)."""

    reason: str
    message: str


@dataclass(frozen=True)
class RowContext:
    """What a handler knows about its row: where it is (file: line), the observing robot's
    index, the run's robots by name, the robots, and the noise defaults (NOISE_DEFAULTS with
    the caller's)."""

    where: str
    robot: int
    index: dict
    robots: tuple
    noise: dict


@dataclass
class LogRows:
    """A log's rows as typed tables, before any front-end: per robot wheel velocities
    (time, v, omega) and planar ground truth (time, x, y, theta); relative-pose motions and
    point measurements as the graph takes them; the raw rows the front-end stage turns into
    observations (`candidates` grouped by (time, observer, sensor, target), `scans` by
    (robot, sensor), `features` as (robot, row), `ellipses` as (observer, target, row, where),
    `markers` as columns); 3D ground truth (times, poses) per robot name; the rows used per
    table as parsed (a front-end's rows count when it makes their set,
    `graphloc_log.FrontEndOutput.used`), the skips and the notes (read and used, but
    said)."""

    manifest: Manifest
    robots: tuple
    index: dict
    noise: dict
    landmarks: tuple  # ids (L,), xyz (L,3), sigma (L,3)
    sink: Sink
    notes: SkipReport
    used: dict
    tables: dict = field(default_factory=dict)  # row kind (Handler.into) -> items, by time
    groundtruth: dict = field(default_factory=dict)  # robot name -> (times, poses) or None
    markers: dict | None = None  # MARKER_COLUMNS -> arrays (log_observations.marker_columns)

    @property
    def skips(self) -> SkipReport:
        return self.sink.report


def _velocity(rec, ctx: RowContext):
    return ctx.robot, (rec.time, rec.v, rec.omega)


def _groundtruth_2d(rec, ctx: RowContext):
    return ctx.robot, (rec.time, rec.x, rec.y, rec.theta)


def _relative_pose_2d(rec, ctx: RowContext):
    sig3 = np.array([rec.sigma_x, rec.sigma_y, rec.sigma_theta])
    if not (sig3 > 0).all() or not rec.time > rec.time0:
        return Skip(
            "bad_relative_pose", f"{ctx.where}: fields 'sigma_*' must be > 0 and time0 < time"
        )
    relative = pose_from_planar(rec.dx, rec.dy, rec.dtheta)
    return Motion(ctx.robot, rec.time0, rec.time, relative, planar_covariance(np.diag(sig3**2)))


def _relative_pose_3d(rec, ctx: RowContext):
    sig6 = np.array(
        [rec.sigma_rx, rec.sigma_ry, rec.sigma_rz, rec.sigma_tx, rec.sigma_ty, rec.sigma_tz]
    )
    q = np.array([rec.qx, rec.qy, rec.qz, rec.qw])
    if not (sig6 > 0).all() or not rec.time > rec.time0 or not 0.5 < np.linalg.norm(q) < 2.0:
        return Skip(
            "bad_relative_pose",
            f"{ctx.where}: fields 'sigma_*' must be > 0, time0 < time and the quaternion unit",
        )
    relative = pose_from_xyz_quat([rec.tx, rec.ty, rec.tz, *q])
    return Motion(ctx.robot, rec.time0, rec.time, relative, np.diag(sig6**2))


def _point(rec, ctx: RowContext):
    """A `bearing`, `range` or `range_bearing` row -> PointMeasurement (noise from the sensor's
    params, else the defaults)."""
    if rec.target == rec.robot:
        return Skip(
            "self_observation", f"{ctx.where}: field 'target': robot {rec.robot} observes itself"
        )
    where, d = ctx.where, ctx.noise
    T_bs, params = ctx.robots[ctx.robot].sensors[rec.sensor]
    E = gtsam.Pose3(T_bs)
    t_idx = ctx.index.get(rec.target, -1)
    lid = -1 if t_idx >= 0 else int(rec.target[len(LANDMARK_PREFIX) :])
    bs = positive_param(params, "bearing_sigma", d["bearing_sigma"], where)
    rs0 = positive_param(params, "range_sigma", d["range_sigma"], where)
    rs1 = positive_param(params, "range_sigma_per_m", d["range_sigma_per_m"], where)
    ri = ctx.robot
    if TABLE_OF[type(rec)] == "bearing":
        v = np.array([rec.x, rec.y, rec.z])
        n = np.linalg.norm(v)
        if not 0.5 < n < 2.0:
            return Skip(
                "not_unit", f"{where}: fields 'x, y, z': |direction| = {n:.3g} is not a unit vector"
            )
        return PointMeasurement("bearing", rec.time, ri, E, t_idx, lid, v / n, np.nan, bs, np.nan)
    if not rec.range > 0:
        return Skip("non_positive_range", f"{where}: field 'range': {rec.range} <= 0")
    rsig = float(np.hypot(rs0, rs1 * rec.range))
    if TABLE_OF[type(rec)] == "range":
        nan3 = np.full(3, np.nan)
        return PointMeasurement("range", rec.time, ri, E, t_idx, lid, nan3, rec.range, np.nan, rsig)
    v = np.array([np.cos(rec.bearing), np.sin(rec.bearing), 0.0])
    return PointMeasurement("range_bearing", rec.time, ri, E, t_idx, lid, v, rec.range, bs, rsig)


def _scan(rec, ctx: RowContext):
    return (ctx.robot, rec.sensor), rec


def _feature(rec, ctx: RowContext):
    return ctx.robot, rec


def _ellipse(rec, ctx: RowContext):
    if rec.target not in ctx.index or rec.target == rec.robot:
        return Skip(
            "unknown_target",
            f"{ctx.where}: field 'target': {rec.target!r} is not another robot",
        )
    return ctx.robot, ctx.index[rec.target], rec, ctx.where


def _candidate(rec, ctx: RowContext):
    if rec.target not in ctx.index:
        return Skip("unknown_target", f"{ctx.where}: field 'target': {rec.target!r} is not a robot")
    norm = float(np.linalg.norm([rec.qw, rec.qx, rec.qy, rec.qz]))
    if not 0.5 < norm < 2.0:
        return Skip(
            "not_unit",
            f"{ctx.where}: fields 'qw, qx, qy, qz': |q| = {norm:.3g} is not a unit quaternion",
        )
    return (rec.time, ctx.robot, rec.sensor, ctx.index[rec.target]), rec


class Handler(NamedTuple):
    """What one table's rows become: `parse(record, RowContext)` -> an item or a `Skip`;
    `into`: the kind of row it is, the list of `LogRows.tables` it joins (rows of one kind in
    time order across robots and tables); `counted`: the row counts as used when parsed
    (False: when the front-end forms its set)."""

    parse: Callable
    into: str
    counted: bool = True


# table kind -> handler (`markers` is read as columns, `log_observations.marker_columns`)
TABLE_HANDLERS: dict[str, Handler] = {
    "odometry": Handler(_velocity, "velocity"),
    "groundtruth": Handler(_groundtruth_2d, "groundtruth"),
    "relative_pose": Handler(_relative_pose_2d, "motions"),
    "relative_pose3": Handler(_relative_pose_3d, "motions"),
    "bearing": Handler(_point, "points"),
    "range": Handler(_point, "points"),
    "range_bearing": Handler(_point, "points"),
    "scans": Handler(_scan, "scans"),
    "features": Handler(_feature, "features", counted=False),
    "ellipses": Handler(_ellipse, "ellipses"),
    "candidates": Handler(_candidate, "candidates", counted=False),
}
ROW_KINDS = tuple(dict.fromkeys(h.into for h in TABLE_HANDLERS.values()))


def read_tum_poses(path: Path) -> tuple[np.ndarray, list]:
    """TUM file (timestamp tx ty tz qx qy qz qw; '#' comments) -> times, Pose3 list. ValueError
    naming file and line on a malformed row."""
    times, poses = [], []
    check_file(path, what="ground-truth TUM file")
    for n, line in text_lines(path):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        parts = text.split()
        try:
            vals = np.array([float(p) for p in parts])
        except ValueError:
            raise ValueError(f"{path}: line {n}: cannot parse {shown(text)} as 8 numbers") from None
        if vals.size != 8 or not np.isfinite(vals).all():
            raise ValueError(
                f"{path}: line {n}: expected 8 finite numbers (timestamp tx ty tz qx qy qz qw)"
            )
        if abs(vals[0]) > MAX_TIME or np.abs(vals[1:4]).max() > MAX_COORDINATE:
            raise ValueError(
                f"{path}: line {n}: field 'timestamp' or 'tx, ty, tz' outside the plausible "
                f"+-{MAX_TIME:g} s / +-{MAX_COORDINATE:g} m"
            )
        if not 0.5 < np.linalg.norm(vals[4:]) < 2.0:
            raise ValueError(f"{path}: line {n}: field 'q': quaternion is not unit")
        if times and vals[0] < times[-1]:
            raise ValueError(f"{path}: line {n}: field 'timestamp': {vals[0]} goes backwards")
        times.append(vals[0])
        poses.append(pose_from_xyz_quat(vals[1:]))
    return np.array(times), poses


def team_robot(r) -> TeamRobot:
    """A manifest robot (`graphloc.manifest.Robot`) as the run's `TeamRobot`."""
    init = None
    if r.initial_pose is not None:
        init = (
            pose_from_planar(*r.initial_pose)
            if len(r.initial_pose) == 3
            else pose_from_xyz_quat(r.initial_pose)
        )
    surface = (
        None
        if r.surface is None
        else SurfacePlane(np.array(r.surface["point"]), np.array(r.surface["normal"]))
    )
    markers = None if r.markers is None else np.array(r.markers, dtype=float)
    sensors = {s.name: (s.body_T_sensor, dict(s.params)) for s in r.sensors}
    return TeamRobot(
        r.name,
        r.kind,
        bool(r.planar),
        bool(r.static),
        init,
        r.initial_sigma,
        surface,
        markers,
        bool(r.identical_markers),
        sensors,
        surface_sigma=None if r.surface is None else r.surface.get("distance_sigma"),
        attitude_sigma=None if r.surface is None else r.surface.get("attitude_sigma"),
        body_axis=tuple((r.surface or {}).get("body_axis", (0.0, 0.0, 1.0))),
        base_radius=r.base_radius,
    )


def read_log_rows(
    root: str | Path,
    on_error: str = "skip",
    defaults: dict | None = None,
    overrides: dict | None = None,
) -> LogRows:
    """A graphloc log directory -> `LogRows`: every row of every table through its table's
    handler (`TABLE_HANDLERS`), in time order across robots and tables; a refused row counted
    as a skip with its reason (`on_error="skip"`) or raised naming file, line and field.
    `defaults`: sensor noise where a sensor's params give none (bearing_sigma [rad],
    range_sigma [m], range_sigma_per_m, pixel_sigma [px], candidate_sigmas (rot, trans));
    `overrides`: the same names, replacing what every sensor's params say (a config file or
    CLI flags)."""
    manifest = read_manifest(root)
    for r in manifest.robots:
        for s in r.sensors:
            s.params.update(overrides or {})
    robots = tuple(team_robot(r) for r in manifest.robots)
    index = {r.name: i for i, r in enumerate(robots)}
    rows = LogRows(
        manifest,
        robots,
        index,
        {**NOISE_DEFAULTS, **(defaults or {})},
        read_landmarks(manifest),
        Sink(on_error, SkipReport()),
        SkipReport(),  # read and used, but said: scans thinned, a bag's stamps re-sorted
        {t: 0 for t in TABLES},
        {kind: [] for kind in ROW_KINDS},
        {r.name: None for r in robots},
    )
    for r in manifest.robots:  # 3D ground truth in TUM files
        path = r.tables.get("groundtruth")
        if path and is_tum(path):
            rows.groundtruth[r.name] = read_tum_poses(manifest.root / path)
            rows.used["groundtruth"] += len(rows.groundtruth[r.name][0])
    streamed = tuple(t for t in TABLES if t in TABLE_HANDLERS)
    records = iter_records(root, tables=streamed, on_error=on_error, report=rows.skips)
    for rec in records:
        table = TABLE_OF[type(rec)]
        where = f"{manifest.root / manifest.robot(rec.robot).tables[table]}: line {rec.line}"
        handler = TABLE_HANDLERS[table]
        item = handler.parse(rec, RowContext(where, index[rec.robot], index, robots, rows.noise))
        if isinstance(item, Skip):
            rows.sink.bad(item.reason, item.message)
            continue
        rows.tables[handler.into].append(item)
        rows.used[table] += handler.counted
    landmark_ids = None if manifest.landmarks_file is None else set(rows.landmarks[0].tolist())
    rows.markers = marker_columns(manifest, robots, index, on_error, rows.skips, landmark_ids)
    return rows
