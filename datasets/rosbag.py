"""ROS bags as graphloc runs (issue 18, bag-loader half): ROS 1 `.bag` files, ROS 2 sqlite3 bag
directories and MCAP files (a bare `.mcap` or a ROS 2 directory of them), read through the
pure-Python `rosbags` library (`rosbags.highlevel.AnyReader`), no ROS installation.

A topics file (YAML, docs/rosbag.md) names the robots in the schema of the log manifest's
`robots` (docs/log_format.md: kind, planar, static, initial_pose, markers, sensors with params
and extrinsics) and maps each topic to one robot and one table of the log format version 2:

- `relative_pose3`: `nav_msgs/Odometry`, `geometry_msgs/PoseWithCovarianceStamped` (increments
  between consecutive messages), `geometry_msgs/PoseStamped` (with fixed `sigmas`);
- `range`: `sensor_msgs/Range`;
- `bearing`: `geometry_msgs/Vector3Stamped`, `geometry_msgs/PointStamped` (a direction in the
  sensor frame);
- `markers`: `vision_msgs/Detection2DArray` (box centre pixel; class id -> target's marker);
- `groundtruth`: `nav_msgs/Odometry`, `geometry_msgs/PoseStamped`, `PoseWithCovarianceStamped`,
  `TransformStamped`.

`import_bag(bag, topics, out)` writes a version-2 log directory (`graphloc.io` tables, the one
reader being `graphloc.datasets.graphloc_log.read_team_run`); the `RosBag` loader of
`graphloc.datasets.open_run` imports into a temporary directory and reads that. The clock is
the messages' header stamps; each topic is sorted by stamp (bag order, i.e. receive time, may
differ). A message that cannot be decoded, has the wrong type for its table, or holds a bad
value is a counted skip naming the bag, topic and message index (`graphloc.io.SkipReport`),
never a crash; the import's skips are kept in the manifest's `meta.import.skips` and merged
into `TeamRun.skips` by the loader.
"""

from __future__ import annotations

import csv
import json
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.eval import write_tum
from graphloc.io import (
    LANDMARK_PREFIX,
    MANIFEST,
    SENSOR_TYPES,
    SkipReport,
    read_manifest,
    write_manifest,
    write_table,
)
from graphloc.datasets.graphloc_log import read_team_run
from graphloc.run import TeamRun, truncate

TOPICS_FILE = "topics.yaml"  # what open_run(BAG) looks for beside (or inside) the bag
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE = "geometry_msgs/msg/PoseStamped"
TRANSFORM = "geometry_msgs/msg/TransformStamped"
RANGE = "sensor_msgs/msg/Range"
VECTOR3 = "geometry_msgs/msg/Vector3Stamped"
POINT = "geometry_msgs/msg/PointStamped"
DETECTIONS = "vision_msgs/msg/Detection2DArray"
# table -> message types a topic of that table may carry
MESSAGE_TYPES = {
    "relative_pose3": (ODOMETRY, POSE_COV, POSE),
    "range": (RANGE,),
    "bearing": (VECTOR3, POINT),
    "markers": (DETECTIONS,),
    "groundtruth": (ODOMETRY, POSE, POSE_COV, TRANSFORM),
}
COVARIANCE_MODES = ("step", "difference")
TOPIC_KEYS = {"robot", "table", "sensor", "target", "targets", "covariance", "sigmas", "classes"}
TABLE_KEYS = {  # topic fields that only some tables take
    "sensor": ("relative_pose3", "range", "bearing", "markers"),
    "target": ("range", "bearing"),
    "targets": ("range", "bearing"),
    "covariance": ("relative_pose3",),
    "sigmas": ("relative_pose3",),
    "classes": ("markers",),
}
# ROS pose covariance order (x, y, z, rot x, rot y, rot z) -> GTSAM Pose3 tangent (rx..tz)
_ROS_TO_GTSAM = (3, 4, 5, 0, 1, 2)


# ---- the topics file -------------------------------------------------------------------------
@dataclass(frozen=True)
class TopicMap:
    """One topic -> (robot, table): the sensor its rows name, the target of range / bearing
    rows (fixed, or by header.frame_id), relative poses' covariance mode or fixed sigmas (GTSAM
    tangent order), and marker class ids -> (target, marker index)."""

    topic: str
    robot: str
    table: str
    sensor: str | None = None
    target: str | None = None
    targets: dict = field(default_factory=dict)
    covariance: str = "step"
    sigmas: tuple | None = None
    classes: dict = field(default_factory=dict)


@dataclass(frozen=True)
class TopicsFile:
    path: Path
    name: str | None
    start_time: float | None
    robots: list
    landmarks: list
    topics: dict  # topic -> TopicMap
    meta: dict


def read_topics(path) -> TopicsFile:
    """Parse and check a topics file (docs/rosbag.md). Every error names the file and field:
    the robots are checked by the manifest reader (`graphloc.io.read_manifest`), each topic's
    robot, table, sensor (of the table's sensor type) and targets against them."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no topics file") from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ValueError(f"{path}: cannot read topics file: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: a topics file is a mapping with fields 'robots' and 'topics'")
    unknown = set(data) - {"name", "start_time", "robots", "landmarks", "topics", "meta"}
    if unknown:
        raise ValueError(f"{path}: unknown field(s) {sorted(unknown)}")
    robots = data.get("robots")
    if not isinstance(robots, list) or not robots:
        raise ValueError(f"{path}: field 'robots' must list the robots (manifest schema)")
    for i, r in enumerate(robots):
        if isinstance(r, dict) and "tables" in r:
            raise ValueError(f"{path}: robots[{i}]: field 'tables' comes from 'topics', not here")
    landmarks = data.get("landmarks") or []
    if not isinstance(landmarks, list):
        raise ValueError(f"{path}: field 'landmarks' must list {{id, xyz, sigma}} entries")
    meta = data.get("meta") or {}
    if not isinstance(meta, dict):
        raise ValueError(f"{path}: field 'meta' must be a mapping")
    start = data.get("start_time")
    body = {"name": data.get("name") or path.stem, "start_time": start, "robots": robots}
    # the robots through the one manifest reader, its errors re-addressed to the topics file
    with tempfile.TemporaryDirectory() as tmp:
        try:
            write_manifest(json.loads(json.dumps(body)), tmp)
        except (TypeError, ValueError) as exc:  # YAML values JSON has no form for (dates, ...)
            raise ValueError(f"{path}: field 'robots': {exc}") from None
        try:
            manifest = read_manifest(tmp)
        except ValueError as exc:
            raise ValueError(str(exc).replace(str(Path(tmp) / MANIFEST), str(path))) from None
    ids = set()
    for j, lm in enumerate(landmarks):
        where = f"{path}: landmarks[{j}]"
        if not isinstance(lm, dict) or not isinstance(lm.get("id"), int):
            raise ValueError(f"{where}: field 'id' must be an integer")
        for key in ("xyz", "sigma"):
            v = lm.get(key, [0, 0, 0] if key == "sigma" else None)
            ok = isinstance(v, list) and len(v) == 3
            if not ok or not all(isinstance(a, (int, float)) and math.isfinite(a) for a in v):
                raise ValueError(f"{where}: field '{key}' must be 3 finite numbers, got {v!r}")
        ids.add(lm["id"])
    topics = data.get("topics")
    if not isinstance(topics, dict) or not topics:
        raise ValueError(f"{path}: field 'topics' must map topic names to {{robot, table, ...}}")
    names = {r.name for r in manifest.robots}
    maps = {}
    for topic, entry in topics.items():
        maps[topic] = _topic_map(path, str(topic), entry, manifest, names, ids)
    return TopicsFile(path, body["name"], start, robots, landmarks, maps, meta)


def _topic_map(path, topic, entry, manifest, names, landmark_ids) -> TopicMap:
    where = f"{path}: topics['{topic}']"
    if not isinstance(entry, dict):
        raise ValueError(f"{where}: must be a mapping {{robot, table, ...}}")
    if unknown := set(entry) - TOPIC_KEYS:
        raise ValueError(
            f"{where}: unknown field(s) {sorted(unknown)}; known: {sorted(TOPIC_KEYS)}"
        )
    table = entry.get("table")
    for key, tables in TABLE_KEYS.items():
        if key in entry and table in MESSAGE_TYPES and table not in tables:
            raise ValueError(
                f"{where}: field '{key}' is for table(s) {', '.join(tables)}, not {table!r}"
            )
    robot = entry.get("robot")
    if robot not in names:
        raise ValueError(
            f"{where}: field 'robot': {robot!r} is not a robot of field 'robots' "
            f"({', '.join(sorted(names))})"
        )
    if table not in MESSAGE_TYPES:
        raise ValueError(
            f"{where}: field 'table': {table!r} unknown; a bag topic fills one of "
            f"{', '.join(MESSAGE_TYPES)}"
        )
    sensor = entry.get("sensor")
    if table != "groundtruth":
        r = manifest.robot(robot)
        s = r.sensor(sensor) if isinstance(sensor, str) else None
        if s is None or s.type != SENSOR_TYPES[table]:
            have = [f"{x.name} ({x.type})" for x in r.sensors]
            raise ValueError(
                f"{where}: field 'sensor': {sensor!r} is not a sensor of type "
                f"{SENSOR_TYPES[table]!r} of robot {robot!r} (it has: {have})"
            )

    def target_ok(t):
        if not isinstance(t, str):
            return False
        if t.startswith(LANDMARK_PREFIX):
            try:
                return int(t[len(LANDMARK_PREFIX) :]) in landmark_ids or not landmark_ids
            except ValueError:
                return False
        return t in names and t != robot

    target, targets = entry.get("target"), entry.get("targets") or {}
    if table in ("range", "bearing"):
        if not isinstance(targets, dict):
            raise ValueError(f"{where}: field 'targets' must map header.frame_id -> target")
        if (target is None) == (not targets):
            raise ValueError(
                f"{where}: give field 'target' (one target) or 'targets' "
                "(header.frame_id -> target), not both or neither"
            )
        for key, t in [("target", target)] if target is not None else targets.items():
            if not target_ok(t):
                raise ValueError(
                    f"{where}: field '{'target' if key == 'target' else 'targets'}'"
                    f": {t!r} is not another robot or a landmark:<id>"
                )
    covariance = entry.get("covariance", "step")
    if covariance not in COVARIANCE_MODES:
        raise ValueError(f"{where}: field 'covariance' must be one of {COVARIANCE_MODES}")
    sigmas = entry.get("sigmas")
    if sigmas is not None:
        ok = isinstance(sigmas, list) and len(sigmas) == 6
        if not ok or not all(isinstance(a, (int, float)) and a > 0 for a in sigmas):
            raise ValueError(
                f"{where}: field 'sigmas' must be 6 numbers > 0 "
                "(rot x, y, z [rad], trans x, y, z [m])"
            )
        sigmas = tuple(float(a) for a in sigmas)
    classes = {}
    if table == "markers":
        raw = entry.get("classes")
        if not isinstance(raw, dict) or not raw:
            raise ValueError(f"{where}: field 'classes' must map class id -> [target, marker]")
        for cid, val in raw.items():
            ok = isinstance(val, list) and len(val) == 2 and isinstance(val[1], int)
            if not ok or not target_ok(val[0]) or val[0].startswith(LANDMARK_PREFIX):
                raise ValueError(f"{where}: field 'classes[{cid}]' must be [robot, marker index]")
            layout = manifest.robot(val[0]).markers or ()
            if not 0 <= val[1] < len(layout):
                raise ValueError(
                    f"{where}: field 'classes[{cid}]': robot {val[0]!r} has no "
                    f"marker {val[1]} (its field 'markers' lists {len(layout)})"
                )
            classes[str(cid)] = (val[0], val[1])
    return TopicMap(topic, robot, table, sensor, target, dict(targets), covariance, sigmas, classes)


def find_topics_file(bag) -> Path:
    """`topics.yaml` inside a ROS 2 bag directory, else beside the bag."""
    bag = Path(bag)
    places = ([bag / TOPICS_FILE] if bag.is_dir() else []) + [bag.parent / TOPICS_FILE]
    for p in places:
        if p.is_file():
            return p
    raise FileNotFoundError(
        f"{bag}: a bag needs a topics file (docs/rosbag.md); none at "
        f"{' or '.join(map(str, places))}; or run `graphloc import {bag} "
        "--topics FILE --out RUN` and then `graphloc smooth RUN`"
    )


def is_bag(path) -> bool:
    """A ROS 1 `.bag` file, an `.mcap` file, or a ROS 2 bag directory (metadata.yaml)."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.is_file() and path.suffix in (".bag", ".mcap")


# ---- reading the bag -------------------------------------------------------------------------
class _Bad(Exception):
    def __init__(self, reason: str, text: str):
        super().__init__(text)
        self.reason = reason


def _stamp(msg) -> float:
    st = msg.header.stamp
    t = st.sec + st.nanosec * 1e-9
    if not math.isfinite(t) or t <= 0:
        raise _Bad("bad_stamp", f"header stamp {st.sec}.{st.nanosec:09d} is not a time")
    return t


def _finite(*values) -> None:
    if not all(math.isfinite(v) for v in values):
        raise _Bad("not_finite", "a field is NaN or inf")


def _pose(msgtype: str, msg):
    """(t (3,), q (qx, qy, qz, qw), 6x6 ROS covariance or None) of a pose message."""
    if msgtype == TRANSFORM:
        p, o, cov = msg.transform.translation, msg.transform.rotation, None
    elif msgtype == POSE:
        p, o, cov = msg.pose.position, msg.pose.orientation, None
    else:  # Odometry, PoseWithCovarianceStamped
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        cov = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6)
    t, q = (p.x, p.y, p.z), (o.x, o.y, o.z, o.w)
    _finite(*t, *q)
    n = math.sqrt(sum(a * a for a in q))
    if not 0.5 < n < 2.0:
        raise _Bad("bad_quaternion", f"orientation |q| = {n:.3g} is not a unit quaternion")
    return np.array(t), tuple(a / n for a in q), cov


def _pose3(t, q) -> gtsam.Pose3:
    return gtsam.Pose3(gtsam.Rot3.Quaternion(q[3], q[0], q[1], q[2]), gtsam.Point3(*t))


def _direction(msgtype: str, msg) -> np.ndarray:
    v = msg.vector if msgtype == VECTOR3 else msg.point
    d = np.array([v.x, v.y, v.z], dtype=float)
    _finite(*d)
    n = float(np.linalg.norm(d))
    if n < 1e-12:
        raise _Bad("bad_direction", "zero vector has no direction")
    return d / n


def _target(m: TopicMap, msg) -> str:
    if m.target is not None:
        return m.target
    frame = msg.header.frame_id
    if frame not in m.targets:
        raise _Bad("unknown_frame", f"header.frame_id {frame!r} is not in field 'targets'")
    return m.targets[frame]


def _detections(m: TopicMap, msg):
    """(target, marker, u, v) of each detection: box centre (vision_msgs 4: center.position;
    older: center.x / center.y) and the best-scoring class id (results[].hypothesis.class_id,
    ROS 1: results[].id)."""
    out, bad = [], []
    for k, det in enumerate(msg.detections):
        if not len(det.results):
            bad.append(f"detection {k} has no results")
            continue
        best = max(det.results, key=lambda r: getattr(getattr(r, "hypothesis", r), "score", 0))
        cid = str(getattr(getattr(best, "hypothesis", best), "class_id", getattr(best, "id", "")))
        if cid not in m.classes:
            bad.append(f"detection {k}: class id {cid!r} is not in field 'classes'")
            continue
        c = det.bbox.center
        c = getattr(c, "position", c)
        u, v = float(c.x), float(c.y)
        if not (math.isfinite(u) and math.isfinite(v)):
            bad.append(f"detection {k}: centre pixel is NaN or inf")
            continue
        out.append((*m.classes[cid], u, v))
    return out, bad


@dataclass
class BagImport:
    """What an import wrote: the log directory, rows per table, the counted skips, topics of
    the bag the topics file does not map, and mapped topics the bag does not hold."""

    root: Path
    rows: dict
    skips: SkipReport
    unmapped: list
    missing: list


def _default_typestore(bag: Path):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if bag.suffix == ".bag" else Stores.ROS2_HUMBLE)


def _read_messages(bag: Path, topics: TopicsFile, skips: SkipReport):
    """Decoded messages of the mapped topics: topic -> [(bag index, msgtype, msg)], bag order;
    plus the bag's unmapped topics. Undecodable messages are counted skips."""
    from rosbags.highlevel import AnyReader, AnyReaderError

    default = _default_typestore(bag)
    per_topic: dict = {t: [] for t in topics.topics}
    try:
        reader = AnyReader([bag], default_typestore=default)
        reader.open()
    except (AnyReaderError, OSError, ValueError, KeyError) as exc:
        raise ValueError(f"{bag}: cannot read bag: {exc}") from None
    try:
        # types the bag does not define (e.g. a ROS 2 sqlite3 bag without definitions)
        have = reader.typestore.fielddefs
        reader.typestore.register({k: v for k, v in default.fielddefs.items() if k not in have})
        unmapped = sorted({c.topic for c in reader.connections} - set(topics.topics))
        conns = [c for c in reader.connections if c.topic in topics.topics]
        index = {t: 0 for t in topics.topics}
        try:
            for conn, _, raw in reader.messages(connections=conns):
                i = index[conn.topic]
                index[conn.topic] += 1
                try:
                    msg = reader.deserialize(raw, conn.msgtype)
                except Exception as exc:  # noqa: BLE001 -- rosbags raises many types for bad bytes
                    skips.add(
                        "undecodable",
                        f"{bag}: topic '{conn.topic}' message {i}: "
                        f"cannot decode {conn.msgtype}: {exc}",
                    )
                    continue
                per_topic[conn.topic].append((i, conn.msgtype, msg))
        except Exception as exc:  # noqa: BLE001 -- a truncated bag ends the messages early
            topic = max(index, key=index.get) if index else "?"
            skips.add(
                "truncated",
                f"{bag}: reading stopped after {sum(index.values())} "
                f"mapped messages (last topic '{topic}'): {exc}",
            )
    finally:
        reader.close()
    return per_topic, unmapped


def import_bag(bag, topics, out) -> BagImport:
    """Convert `bag` with the topics file `topics` (path or TopicsFile) into a log directory
    `out` (docs/log_format.md, version 2; docs/rosbag.md). Returns what was written."""
    bag, out = Path(bag), Path(out)
    tf = topics if isinstance(topics, TopicsFile) else read_topics(topics)
    if not is_bag(bag):
        raise FileNotFoundError(
            f"{bag}: not a ROS bag (a .bag or .mcap file, or a directory with metadata.yaml)"
        )
    skips = SkipReport()
    per_topic, unmapped = _read_messages(bag, tf, skips)
    rows: dict = {}  # (robot, table) -> [row tuple starting with time]
    missing = []
    for topic, msgs in per_topic.items():
        m = tf.topics[topic]
        if not msgs:
            missing.append(topic)
            skips.add("missing_topic", f"{bag}: topic '{topic}' ({tf.path}) has no messages")
            continue
        rows.setdefault((m.robot, m.table), []).extend(_topic_rows(bag, m, msgs, skips))
    out.mkdir(parents=True, exist_ok=True)
    written = {}
    robots = []
    for r in tf.robots:
        name = r["name"]
        tables = {}
        for (robot, table), rs in sorted(rows.items()):
            if robot != name or not rs:
                continue
            rs.sort(key=lambda row: row[0])
            (out / name).mkdir(exist_ok=True)
            rel = f"{name}/{'groundtruth.tum' if table == 'groundtruth' else table + '.csv'}"
            _write_table(out / rel, table, rs)
            tables[table] = rel
            written[table] = written.get(table, 0) + len(rs)
        robots.append({**r, "tables": tables})
    body = {
        "name": tf.name,
        "start_time": tf.start_time,
        "robots": robots,
        "meta": {
            **tf.meta,
            "import": {"source": str(bag), "topics": str(tf.path), "skips": skips.as_dict()},
        },
    }
    if tf.landmarks:
        with open(out / "landmarks.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["id", "x", "y", "z", "sigma_x", "sigma_y", "sigma_z"])
            for lm in tf.landmarks:
                w.writerow(
                    [
                        lm["id"],
                        *map(repr, map(float, lm["xyz"])),
                        *map(repr, map(float, lm.get("sigma", [0, 0, 0]))),
                    ]
                )
        body["landmarks"] = {"file": "landmarks.csv"}
    write_manifest(body, out)
    return BagImport(out, written, skips, unmapped, missing)


def _topic_rows(bag: Path, m: TopicMap, msgs: list, skips: SkipReport) -> list:
    """Rows of one topic's messages, sorted by header stamp (stable: bag order breaks ties)."""
    stamped = []
    for i, msgtype, msg in msgs:
        where = f"{bag}: topic '{m.topic}' message {i}"
        if msgtype not in MESSAGE_TYPES[m.table]:
            skips.add(
                "wrong_type",
                f"{where}: {msgtype} cannot fill table '{m.table}' "
                f"(takes {', '.join(MESSAGE_TYPES[m.table])})",
            )
            continue
        try:
            stamped.append((_stamp(msg), i, msgtype, msg))
        except (_Bad, AttributeError) as exc:
            skips.add(getattr(exc, "reason", "malformed"), f"{where}: {exc}")
    stamped.sort(key=lambda s: (s[0], s[1]))
    out, prev = [], None
    for t, i, msgtype, msg in stamped:
        where = f"{bag}: topic '{m.topic}' message {i} (stamp {t:.9f})"
        try:
            if m.table in ("relative_pose3", "groundtruth"):
                xyz, q, cov = _pose(msgtype, msg)
                if m.table == "groundtruth":
                    out.append((t, *xyz, *q))
                    continue
                if prev is not None:
                    row = _increment(m, prev, (t, xyz, q, cov), msgtype)
                    if row is not None:
                        out.append(row)
                prev = (t, xyz, q, cov)
            elif m.table == "range":
                r = float(msg.range)
                _finite(r)
                lo, hi = float(msg.min_range), float(msg.max_range)
                if r <= 0 or r < lo or (hi > lo and r > hi):
                    raise _Bad(
                        "out_of_range", f"range {r:g} m outside [{lo:g}, {hi:g}] (or not > 0)"
                    )
                out.append((t, m.sensor, _target(m, msg), r))
            elif m.table == "bearing":
                out.append((t, m.sensor, _target(m, msg), *_direction(msgtype, msg)))
            else:  # markers
                dets, bad = _detections(m, msg)
                for text in bad:
                    skips.add("bad_detection", f"{where}: {text}")
                out.extend((t, m.sensor, tgt, k, u, v) for tgt, k, u, v in dets)
        except _Bad as exc:
            skips.add(exc.reason, f"{where}: {exc}")
        except (AttributeError, TypeError, ValueError) as exc:
            skips.add("malformed", f"{where}: {exc}")
    return out


def _increment(m: TopicMap, prev, cur, msgtype: str):
    """relative_pose3 row from the pose at `prev` to the pose at `cur`, in the frame at prev;
    sigmas: the topic's fixed `sigmas`, else the current message's covariance diagonal
    ("step": the covariance of the step since the previous message) or the growth of the
    diagonal ("difference": an accumulating dead-reckoning covariance)."""
    t0, xyz0, q0, cov0 = prev
    t, xyz, q, cov = cur
    if not t > t0:
        raise _Bad("duplicate_stamp", f"stamp equals the previous message's ({t0:.9f})")
    if m.sigmas is not None:
        sig = np.array(m.sigmas)
    else:
        if cov is None:
            raise _Bad("no_covariance", f"{msgtype} carries no covariance: give field 'sigmas'")
        var = np.diag(cov) - (np.diag(cov0) if m.covariance == "difference" else 0.0)
        sig = np.sqrt(np.clip(var, 0.0, None))[list(_ROS_TO_GTSAM)]
        if not (np.isfinite(sig).all() and (sig > 0).all()):
            raise _Bad(
                "no_covariance",
                f"covariance diagonal gives sigmas {sig.tolist()} "
                f"({m.covariance}); give field 'sigmas'",
            )
    rel = _pose3(xyz0, q0).between(_pose3(xyz, q))
    qw, qx, qy, qz = rel.rotation().toQuaternion().coeffs()[[3, 0, 1, 2]]
    return (t, m.sensor, t0, *rel.translation(), qx, qy, qz, qw, *sig)


def _write_table(path: Path, table: str, rows: list) -> None:
    if table != "groundtruth":
        write_table(path, table, rows)
        return
    a = np.asarray(rows, dtype=float)  # timestamp tx ty tz qx qy qz qw -> the one TUM writer
    poses = np.tile(np.eye(4), (len(a), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(a[:, 4:8]).as_matrix()
    poses[:, :3, 3] = a[:, 1:4]
    write_tum(path, a[:, 0], poses)


# ---- the loader (graphloc.datasets.loaders protocol) -----------------------------------------
class RosBag:
    """A ROS 1 / ROS 2 / MCAP bag with a `topics.yaml` beside it (docs/rosbag.md): imported
    into a temporary log directory and read by `graphloc.datasets.graphloc_log.read_team_run`."""

    name = "rosbag"
    expects = f"a .bag / .mcap file or a metadata.yaml directory, with {TOPICS_FILE}"

    def matches(self, path: Path) -> bool:
        return is_bag(path)

    def load(self, path: Path, duration: float | None, noise: dict | None, topics=None) -> TeamRun:
        topics = topics if topics is not None else find_topics_file(path)
        with tempfile.TemporaryDirectory(prefix="graphloc-bag-") as tmp:
            import_bag(path, topics, tmp)
            run = read_team_run(tmp, overrides=noise)
        # the temporary tables are gone: their rows' messages name the bag's import instead
        run.skips.examples[:] = [m.replace(tmp, f"{path} (imported)") for m in run.skips.examples]
        return run if duration is None else truncate(run, duration)
