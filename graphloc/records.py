"""The records of the graphloc log format (docs/log_format.md): one frozen dataclass per table,
whose fields after `robot` are the table's CSV columns; `TABLES` maps table names to them and
`SENSOR_TYPES` says which sensor type each table's `sensor` column must name. Read by
`graphloc.io.iter_table`, written by `graphloc.log_writer.write_table`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

LANDMARK_PREFIX = "landmark:"
LANDMARK_COLUMNS = ["id", "x", "y", "z", "sigma_x", "sigma_y", "sigma_z"]  # landmarks.csv

# plausible range of a numeric column, by column name (a row outside it is counted as
# "implausible", naming file, line and field): generous for any lab or field robot, tight enough
# that a unit error or an overflowed value (1e308) never reaches a factor
MAX_TIME = 1e11  # s (Unix time until the year 5138; relative clocks start near 0)
MAX_COORDINATE = 1e6  # m, translations and positions
MAX_ANGLE = 1e4  # rad (angles may be unwrapped)
MAX_SIGMA = 1e6  # m or rad
MAX_PIXEL = 1e6  # px
PLAUSIBLE = {
    "time": (-MAX_TIME, MAX_TIME),
    "time0": (-MAX_TIME, MAX_TIME),
    "v": (-100.0, 100.0),  # m/s
    "omega": (-100.0, 100.0),  # rad/s
    "range": (-MAX_COORDINATE, MAX_COORDINATE),  # <= 0 is its own reason (non_positive_range)
    "bearing": (-MAX_ANGLE, MAX_ANGLE),
    "dtheta": (-MAX_ANGLE, MAX_ANGLE),
    "theta": (-MAX_ANGLE, MAX_ANGLE),
    "score": (0.0, 1e300),
    "marker": (0, 1_000_000),
    "k": (0, 1_000_000),
    "id": (0, 2**31 - 1),
    "track": (0, 2**31 - 1),
    **{q: (-2.0, 2.0) for q in ("qx", "qy", "qz", "qw")},
    **{c: (-MAX_COORDINATE, MAX_COORDINATE) for c in ("x", "y", "z", "dx", "dy")},
    **{c: (-MAX_COORDINATE, MAX_COORDINATE) for c in ("tx", "ty", "tz")},
    **{
        f"sigma_{c}": (0.0, MAX_SIGMA)
        for c in ("x", "y", "z", "theta", "rx", "ry", "rz", "tx", "ty", "tz")
    },
}


def plausible(table: str) -> dict:
    """Column name -> (low, high) of `table` (a `v` is a speed in odometry, a pixel in
    markers)."""
    if table in ("markers", "features"):
        return {**PLAUSIBLE, "u": (-MAX_PIXEL, MAX_PIXEL), "v": (-MAX_PIXEL, MAX_PIXEL)}
    if table == "ellipses":
        return {
            **PLAUSIBLE,
            "angle": (-MAX_ANGLE, MAX_ANGLE),  # degrees
            **{c: (-MAX_PIXEL, MAX_PIXEL) for c in ("u0", "v0")},
            **{c: (0.0, MAX_PIXEL) for c in ("width", "height", "centre_sigma", "radius_sigma")},
        }
    return PLAUSIBLE


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
class FeaturePixel(_Row):
    """Pixel (u, v) of feature track `track` (a KLT track: one scene point) in camera `sensor`
    (seed 003 II-B)."""

    time: float
    robot: str
    sensor: str
    track: int
    u: float
    v: float


@dataclass(frozen=True)
class EllipseObservation(_Row):
    """The ellipse a teammate's circular base makes in camera `sensor` (seed 003 II, eqs. 1-4):
    centre (u0, v0), full width and height [px] and angle [deg] (OpenCV RotatedRect convention)
    in ideal (undistorted) pixels, with the accuracy of its centre and of its radius [px]. The
    target robot's `base_radius` (manifest) gives the metric scale."""

    time: float
    robot: str
    sensor: str
    target: str
    u0: float
    v0: float
    width: float
    height: float
    angle: float
    centre_sigma: float
    radius_sigma: float


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
    "features": FeaturePixel,
    "ellipses": EllipseObservation,
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
    "features": "camera",
    "ellipses": "camera",
    "candidates": "camera",
    "scans": "scanner",
}


def columns(table: str) -> list[str]:
    """CSV header of `table`: every record field except `robot` (the robot is the file's owner)."""
    return [f.name for f in fields(TABLES[table]) if f.name not in ("robot", "line")]
