"""A graphloc log directory written as a ROS bag (ROS 1 `.bag`, ROS 2 sqlite3 or MCAP) with the
topics file that reads it back (docs/rosbag.md): the inverse of `graphloc import` for the tables
the scenarios write. Used to check that a run read through a bag gives the estimates of the run
read directly (tests/datasets/test_rosbag.py, tests/datasets/test_rosbag_properties.py,
tests/live/test_live_io.py)."""

from __future__ import annotations

import csv
from pathlib import Path

import gtsam
import numpy as np

from graphloc.datasets.rosbag import typestore
from graphloc.manifest import MANIFEST, read_manifest
from graphloc.mapping.io import read_points
from graphloc.structured import read_json

KINDS = ("ros1", "sqlite3", "mcap")
EXPORTED = ("relative_pose3", "range", "bearing", "markers", "scans", "groundtruth")


class _Msgs:
    """Message builders on one type store (ROS 1 headers carry a seq)."""

    def __init__(self, ts, ros1: bool):
        self.ts, self.ros1, self.seq = ts, ros1, 0

    def __call__(self, msgtype: str, **fields):
        return self.ts.types[msgtype](**fields)

    def header(self, t: float, frame: str = "map"):
        sec = int(np.floor(t))
        stamp = self("builtin_interfaces/msg/Time", sec=sec, nanosec=int(round((t - sec) * 1e9)))
        self.seq += 1
        extra = {"seq": self.seq} if self.ros1 else {}
        return self("std_msgs/msg/Header", stamp=stamp, frame_id=frame, **extra)

    def pose(self, p: gtsam.Pose3):
        q, t = p.rotation().toQuaternion(), p.translation()
        return self(
            "geometry_msgs/msg/Pose",
            position=self("geometry_msgs/msg/Point", x=t[0], y=t[1], z=t[2]),
            orientation=self("geometry_msgs/msg/Quaternion", x=q.x(), y=q.y(), z=q.z(), w=q.w()),
        )


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return [r for r in csv.DictReader(fh) if r and not next(iter(r.values())).startswith("#")]


def _odometry(m: _Msgs, path: Path, robot: str) -> list:
    """relative_pose3 rows -> per sensor, the chained poses as PoseWithCovarianceStamped (the
    covariance of the step into each pose; ROS order x y z rx ry rz)."""
    out, chains = [], {}
    for row in _rows(path):
        chains.setdefault(row["sensor"], []).append(row)
    for sensor, rows in chains.items():
        topic = f"/{robot}/{sensor}/odom"
        pose, prev = gtsam.Pose3(), None
        for k, r in enumerate(rows):
            t0, t = float(r["time0"]), float(r["time"])
            if prev is not None and t0 != prev:
                raise ValueError(
                    f"{path}: row {k + 1}: field 'time0' {t0!r} is not the previous row's time "
                    f"{prev!r}: only a chain of steps is a pose topic"
                )
            sig = np.array([float(r[f"sigma_{a}"]) for a in ("rx", "ry", "rz", "tx", "ty", "tz")])
            cov = np.diag(np.r_[sig[3:], sig[:3]] ** 2)
            if prev is None:
                out.append((topic, _pose_cov(m, t0, pose, cov)))
            q = [float(r[a]) for a in ("qw", "qx", "qy", "qz")]
            step = gtsam.Pose3(
                gtsam.Rot3.Quaternion(*q), gtsam.Point3(*(float(r[a]) for a in ("tx", "ty", "tz")))
            )
            pose = pose.compose(step)
            out.append((topic, _pose_cov(m, t, pose, cov)))
            prev = t
    return out


def _pose_cov(m: _Msgs, t: float, pose: gtsam.Pose3, cov: np.ndarray):
    msgtype = "geometry_msgs/msg/PoseWithCovarianceStamped"
    body = m("geometry_msgs/msg/PoseWithCovariance", pose=m.pose(pose), covariance=cov.ravel())
    return msgtype, t, m(msgtype, header=m.header(t, "odom"), pose=body)


def _markers(m: _Msgs, path: Path, robot: str) -> tuple[list, dict]:
    """markers rows -> one Detection2DArray per (time, sensor); class id "TARGET:MARKER"."""
    msgtype = "vision_msgs/msg/Detection2DArray"
    frames, classes = {}, {}
    for r in _rows(path):
        frames.setdefault((float(r["time"]), r["sensor"]), []).append(r)
        classes[f"{r['target']}:{r['marker']}"] = [r["target"], int(r["marker"])]
    zero = m(
        "geometry_msgs/msg/PoseWithCovariance", pose=m.pose(gtsam.Pose3()), covariance=np.zeros(36)
    )
    out = []
    for (t, sensor), rows in frames.items():
        dets = []
        for r in rows:
            hyp = m(
                "vision_msgs/msg/ObjectHypothesisWithPose",
                hypothesis=m(
                    "vision_msgs/msg/ObjectHypothesis",
                    class_id=f"{r['target']}:{r['marker']}",
                    score=1.0,
                ),
                pose=zero,
            )
            centre = m(
                "vision_msgs/msg/Pose2D",
                position=m("vision_msgs/msg/Point2D", x=float(r["u"]), y=float(r["v"])),
                theta=0.0,
            )
            box = m("vision_msgs/msg/BoundingBox2D", center=centre, size_x=1.0, size_y=1.0)
            dets.append(
                m(
                    "vision_msgs/msg/Detection2D",
                    header=m.header(t, sensor),
                    results=[hyp],
                    bbox=box,
                    id="",
                )
            )
        msg = m(msgtype, header=m.header(t, sensor), detections=dets)
        out.append((f"/{robot}/{sensor}/detections", (msgtype, t, msg)))
    return out, classes


def _scans(m: _Msgs, path: Path, root: Path, robot: str) -> list:
    msgtype = "sensor_msgs/msg/PointCloud2"
    fields = [
        m("sensor_msgs/msg/PointField", name=n, offset=8 * i, datatype=8, count=1)
        for i, n in enumerate("xyz")
    ]
    out = []
    for r in _rows(path):
        pts = np.ascontiguousarray(read_points(root / r["path"]), dtype="<f8")
        t = float(r["time"])
        msg = m(
            msgtype,
            header=m.header(t, r["sensor"]),
            height=1,
            width=len(pts),
            fields=fields,
            is_bigendian=False,
            point_step=24,
            row_step=24 * len(pts),
            data=np.frombuffer(pts.tobytes(), dtype=np.uint8),
            is_dense=True,
        )
        out.append((f"/{robot}/{r['sensor']}/points", (msgtype, t, msg)))
    return out


def _pointing(m: _Msgs, path: Path, robot: str, table: str) -> tuple[list, dict]:
    """range / bearing rows -> one topic per sensor (sensor_msgs/Range, geometry_msgs/
    Vector3Stamped), one message per row with header.frame_id = the target's name (the topic's
    'targets' map, frame -> target)."""
    out, targets = [], {}
    for r in _rows(path):
        t, target = float(r["time"]), r["target"]
        header = m.header(t, target)
        if table == "range":
            msgtype = "sensor_msgs/msg/Range"
            msg = m(
                msgtype,
                header=header,
                radiation_type=0,
                field_of_view=0.0,
                min_range=0.0,
                max_range=0.0,
                range=float(r["range"]),
            )
        else:
            msgtype = "geometry_msgs/msg/Vector3Stamped"
            v = m("geometry_msgs/msg/Vector3", **{a: float(r[a]) for a in ("x", "y", "z")})
            msg = m(msgtype, header=header, vector=v)
        topic = f"/{robot}/{r['sensor']}/{table}"
        targets.setdefault(topic, {})[target] = target
        out.append((topic, (msgtype, t, msg)))
    return out, targets


def _groundtruth(m: _Msgs, path: Path, robot: str) -> list:
    if path.suffix != ".tum":
        raise ValueError(f"{path}: planar ground truth (.csv) has no bag form here; 3D (.tum) only")
    msgtype = "geometry_msgs/msg/PoseStamped"
    out = []
    for line in path.read_text().splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        t, x, y, z, qx, qy, qz, qw = map(float, line.split())
        pose = gtsam.Pose3(gtsam.Rot3.Quaternion(qw, qx, qy, qz), gtsam.Point3(x, y, z))
        msg = m(msgtype, header=m.header(t), pose=m.pose(pose))
        out.append((f"/{robot}/groundtruth", (msgtype, t, msg)))
    return out


def export_bag(log_dir, bag, kind: str) -> Path:
    """Write the log directory `log_dir` as a bag at `bag` (`kind`: ros1, sqlite3 or mcap) and
    the topics file that maps it back (`topics.yaml` beside a `.bag`, inside a ROS 2 bag
    directory). Returns the topics file. Tables other than EXPORTED are an error naming them."""
    import yaml
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    if kind not in KINDS:
        raise ValueError(f"bag kind must be one of {KINDS}, got {kind!r}")
    root, bag = Path(log_dir), Path(bag)
    manifest = read_manifest(root)
    raw = read_json(root / MANIFEST, what="log manifest")
    if "landmarks" in raw:
        raise ValueError(f"{root / MANIFEST}: landmarks have no bag form here")
    ts = typestore(kind)
    m = _Msgs(ts, kind == "ros1")
    messages, topics = [], {}
    for robot in manifest.robots:
        for table, rel in robot.tables.items():
            path = root / rel
            if table not in EXPORTED:
                raise ValueError(f"{path}: table '{table}' has no bag form here ({EXPORTED})")
            if table == "relative_pose3":
                got = _odometry(m, path, robot.name)
            elif table == "markers":
                got, classes = _markers(m, path, robot.name)
            elif table == "scans":
                got = _scans(m, path, root, robot.name)
            elif table in ("range", "bearing"):
                got, targets = _pointing(m, path, robot.name, table)
            else:
                got = _groundtruth(m, path, robot.name)
            for topic, msg in got:
                messages.append((topic, *msg))
                if topic in topics:
                    continue
                entry = {"robot": robot.name, "table": table}
                if table != "groundtruth":
                    entry["sensor"] = topic.split("/")[2]
                if table == "markers":
                    entry["classes"] = classes
                if table in ("range", "bearing"):
                    entry["targets"] = targets[topic]
                topics[topic] = entry
    if kind == "ros1":
        writer = Writer1(bag)
    else:
        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(bag, version=9, storage_plugin=plugin)
    with writer:
        conns = {}
        for topic, msgtype, t, msg in sorted(messages, key=lambda x: x[2]):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            data = (
                ts.serialize_ros1(msg, msgtype)
                if kind == "ros1"
                else ts.serialize_cdr(msg, msgtype)
            )
            writer.write(conns[topic], int(round(t * 1e9)), data)
    robots = [{k: v for k, v in r.items() if k != "tables"} for r in raw["robots"]]
    body = {"name": raw.get("name"), "start_time": raw.get("start_time"), "robots": robots}
    body["topics"] = topics
    out = (bag if bag.is_dir() else bag.parent) / "topics.yaml"
    out.write_text(yaml.safe_dump(body, sort_keys=False))
    return out
