"""The topics file of a bag import (docs/rosbag.md): the robots in the schema of the log
manifest's `robots` (docs/log_format.md), which topic fills which table of which robot, and
(optionally) the tf frames of each robot's body and sensors, from which `tf` / `tf_static`
give the sensors' extrinsics. `read_topics(path) -> TopicsFile`; every error names the file
and the field."""

from __future__ import annotations

import json
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from graphloc.records import LANDMARK_PREFIX, SENSOR_TYPES
from graphloc.manifest import MANIFEST, read_manifest, write_manifest
from graphloc.names import safe_name
from graphloc.structured import dumps_json, read_yaml
from graphloc.vision.markers import MarkerDetectorConfig

TOPICS_FILE = "topics.yaml"  # what open_run(BAG) looks for beside (or inside) the bag
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE = "geometry_msgs/msg/PoseStamped"
TWIST = "geometry_msgs/msg/TwistStamped"
TRANSFORM = "geometry_msgs/msg/TransformStamped"
RANGE = "sensor_msgs/msg/Range"
VECTOR3 = "geometry_msgs/msg/Vector3Stamped"
POINT = "geometry_msgs/msg/PointStamped"
DETECTIONS = "vision_msgs/msg/Detection2DArray"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
CLOUD = "sensor_msgs/msg/PointCloud2"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
TF_TOPICS = ("/tf_static", "/tf")  # read when the topics file has 'frames'
# table -> message types a topic of that table may carry
MESSAGE_TYPES = {
    "odometry": (TWIST, ODOMETRY),
    "relative_pose3": (ODOMETRY, POSE_COV, POSE),
    "range": (RANGE,),
    "bearing": (VECTOR3, POINT),
    "markers": (DETECTIONS, IMAGE, COMPRESSED),
    "scans": (CLOUD,),
    "groundtruth": (ODOMETRY, POSE, POSE_COV, TRANSFORM),
}
COVARIANCE_MODES = ("step", "difference")
TABLE_KEYS = {  # topic fields that only some tables take
    "sensor": ("odometry", "relative_pose3", "range", "bearing", "markers", "scans"),
    "target": ("range", "bearing", "markers"),
    "targets": ("range", "bearing"),
    "covariance": ("relative_pose3",),
    "sigmas": ("relative_pose3",),
    "classes": ("markers",),
    "camera_info": ("markers",),
    "detector": ("markers",),
}
TOPIC_KEYS = {"robot", "table", *TABLE_KEYS}


@dataclass(frozen=True)
class TopicMap:
    """One topic -> (robot, table): the sensor its rows name, the target of range / bearing
    rows (fixed, or by header.frame_id) or of image markers, relative poses' covariance mode or
    fixed sigmas (GTSAM tangent order), marker class ids -> (target, marker index) of
    detections, the CameraInfo topic of a camera and the marker detector's options (images)."""

    topic: str
    robot: str
    table: str
    sensor: str | None = None
    target: str | None = None
    targets: dict = field(default_factory=dict)
    covariance: str = "step"
    sigmas: tuple | None = None
    classes: dict = field(default_factory=dict)
    camera_info: str | None = None
    detector: dict = field(default_factory=dict)


@dataclass(frozen=True)
class TopicsFile:
    path: Path
    name: str | None
    start_time: float | None
    robots: list
    landmarks: list
    topics: dict  # topic -> TopicMap
    meta: dict
    frames: dict = field(default_factory=dict)  # robot -> {"body": frame, "sensors": {s: frame}}


def read_topics(path) -> TopicsFile:
    """Parse and check a topics file (docs/rosbag.md). Every error names the file and field:
    the robots are checked by the manifest reader (`graphloc.manifest.read_manifest`), each topic's
    robot, table, sensor (of the table's sensor type) and targets against them."""
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        raise FileNotFoundError(f"{path}: no topics file")
    data = read_yaml(path, what="topics file")
    if not isinstance(data, dict):
        raise ValueError(f"{path}: a topics file is a mapping with fields 'robots' and 'topics'")
    unknown = set(data) - {"name", "start_time", "robots", "landmarks", "topics", "meta", "frames"}
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
    body = {"name": data.get("name") or safe_name(path.stem), "start_time": start, "robots": robots}
    # the robots through the one manifest reader, its errors re-addressed to the topics file
    with tempfile.TemporaryDirectory() as tmp:
        try:
            write_manifest(json.loads(dumps_json(body)), tmp)
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
    frames = _frames(path, data.get("frames") or {}, robots, manifest)
    return TopicsFile(path, body["name"], start, robots, landmarks, maps, meta, frames)


def _frames(path, frames, robots, manifest) -> dict:
    """`frames: {robot: {body: FRAME, sensors: {sensor: FRAME}}}`: each listed sensor's
    extrinsics come from tf; a sensor that states `extrinsics` too is an error."""
    if not isinstance(frames, dict):
        raise ValueError(f"{path}: field 'frames' must map robot -> {{body, sensors}}")
    out = {}
    for name, entry in frames.items():
        where = f"{path}: frames['{name}']"
        if not isinstance(name, str) or manifest.robot(name) is None:
            raise ValueError(f"{where}: {name!r} is not a robot of field 'robots'")
        ok = isinstance(entry, dict) and isinstance(entry.get("body"), str)
        ok = ok and isinstance(entry.get("sensors", {}), dict)
        if not ok or set(entry) - {"body", "sensors"}:
            raise ValueError(f"{where}: must be {{body: FRAME, sensors: {{SENSOR: FRAME}}}}")
        raw = next(r for r in robots if r.get("name") == name)
        given = {s.get("name"): s for s in raw.get("sensors", []) if isinstance(s, dict)}
        for sensor, frame in entry.get("sensors", {}).items():
            if sensor not in given or not isinstance(frame, str):
                raise ValueError(
                    f"{where}: field 'sensors[{sensor}]': not a sensor of robot {name!r} "
                    "with a frame name"
                )
            if "extrinsics" in given[sensor]:
                raise ValueError(
                    f"{where}: field 'sensors[{sensor}]': the sensor states 'extrinsics' too; "
                    "give one (tf frame or extrinsics)"
                )
        out[name] = {"body": entry["body"], "sensors": dict(entry.get("sensors", {}))}
    return out


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
    classes = _classes(where, entry, manifest, target_ok) if table == "markers" else {}
    camera_info = entry.get("camera_info")
    if camera_info is not None and not isinstance(camera_info, str):
        raise ValueError(f"{where}: field 'camera_info' must be a topic name")
    detector = entry.get("detector") or {}
    try:
        MarkerDetectorConfig(**{**detector, "expected": 4})
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: field 'detector': {exc}") from None
    return TopicMap(
        topic,
        robot,
        table,
        sensor,
        target,
        dict(targets),
        covariance,
        sigmas,
        classes,
        camera_info,
        dict(detector),
    )


def _classes(where, entry, manifest, target_ok) -> dict:
    """Detections: `classes` (class id -> [robot, marker index]); images: `target`, a robot
    with four `identical_markers` (the detector's blobs carry no identity: seed 001)."""
    raw, target = entry.get("classes"), entry.get("target")
    if (raw is None) == (target is None):
        raise ValueError(
            f"{where}: give field 'classes' (Detection2DArray: class id -> [robot, marker]) or "
            "'target' (images: the robot whose markers the detector finds), not both or neither"
        )
    if target is not None:
        r = manifest.robot(target) if target_ok(target) else None
        if r is None or not r.identical_markers or len(r.markers or ()) != 4:
            raise ValueError(
                f"{where}: field 'target': {target!r} must be another robot with four "
                "identical_markers (image blobs carry no marker identity)"
            )
        return {}
    if not isinstance(raw, dict) or not raw:
        raise ValueError(f"{where}: field 'classes' must map class id -> [target, marker]")
    classes = {}
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
    return classes


def find_topics_file(bag) -> Path:
    """`topics.yaml` inside a ROS 2 bag directory, else beside the bag."""
    bag = Path(bag)
    places = ([bag / TOPICS_FILE] if bag.is_dir() else []) + [bag.parent / TOPICS_FILE]
    for p in places:
        if p.is_file():
            return p
    raise FileNotFoundError(
        f"{bag}: a bag needs a topics file (docs/rosbag.md); none at "
        f"{' or '.join(map(str, places))}; name one with --topics FILE"
    )
