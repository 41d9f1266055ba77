"""ROS 2 topics in and poses out over Cyclone DDS without a ROS installation (`graphloc[live]`):
`Ros2Source` (a topics file's topics), `Ros2LogSource` (a log's lines as
`graphloc_msgs/msg/LogRow`), `Ros2Sink` (pose, path and tf per robot); quality of service and
domain as docs/live.md says."""

from __future__ import annotations

import os
import queue
import threading
import time

import numpy as np

from graphloc.datasets.rosbag_topics import MESSAGE_TYPES, TopicsFile
from graphloc.live.ros2_types import as_message, dds_topic, idl_type
from graphloc.live.topics import LiveTopics

POSE_TYPE = "geometry_msgs/msg/PoseWithCovarianceStamped"
PATH_TYPE = "nav_msgs/msg/Path"
TF_TYPE = "tf2_msgs/msg/TFMessage"
FRAME = "map"
KEEP_POSES = 10000  # pose and tf messages a late reader gets (transient-local history)
LOG_ROW = "graphloc_msgs/msg/LogRow"  # a log table's line (graphloc.live.ros2_types)
# GTSAM Pose3 tangent (rx ry rz tx ty tz) -> ROS pose covariance order (x y z rx ry rz)
_GTSAM_TO_ROS = [3, 4, 5, 0, 1, 2]


def domain_id() -> int:
    """ROS 2's domain: ROS_DOMAIN_ID (default 0); ValueError naming it if not an integer."""
    text = os.environ.get("ROS_DOMAIN_ID", "0").strip() or "0"
    try:
        value = int(text)
    except ValueError:
        raise ValueError(f"ROS_DOMAIN_ID={text!r} is not an integer") from None
    if not 0 <= value <= 232:
        raise ValueError(f"ROS_DOMAIN_ID={value} is outside DDS's domains 0..232")
    return value


def qos(keep: int | None = None):
    """Reliable, keep-all (`keep` None: the rows in) or transient-local keeping the last `keep`
    messages (the poses out: a reader that joins late gets them, as ROS 2's latched topics)."""
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration

    reliable = Policy.Reliability.Reliable(duration(seconds=1))
    if keep is None:
        return Qos(reliable, Policy.History.KeepAll)
    return Qos(reliable, Policy.History.KeepLast(keep), Policy.Durability.TransientLocal)


def participant(domain: int | None = None):
    from cyclonedds.domain import DomainParticipant

    return DomainParticipant(domain_id() if domain is None else domain)


def ros_type(dds_type_name: str) -> str | None:
    """`pkg::msg::dds_::Type_` -> `pkg/msg/Type` (None for a name of another form)."""
    parts = dds_type_name.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        return None
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"


def stamp_of(t: float) -> dict:
    """builtin_interfaces/Time fields of a time [s] (rounded to the nanosecond)."""
    ns = int(round(t * 1e9))
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


class _Readers:
    """DDS readers whose samples queue up with their arrival time (a listener, on Cyclone's
    thread); `_take` hands them to the caller's thread in arrival order."""

    def __init__(self, dp=None):
        self.dp = dp if dp is not None else participant()
        self._queue: queue.Queue = queue.Queue()
        self._readers: dict = {}  # ROS topic -> reader (None: refused)
        self.received = 0

    def _subscribe(self, topic: str, msgtype: str) -> None:
        from cyclonedds.core import Listener
        from cyclonedds.sub import DataReader, InvalidSample
        from cyclonedds.topic import Topic

        put = self._queue.put

        def on_data(reader):
            now = time.perf_counter()
            for sample in reader.take(N=1024):
                if not isinstance(sample, InvalidSample):  # a writer gone, not data
                    put((now, topic, msgtype, sample))

        dds = Topic(self.dp, dds_topic(topic), idl_type(msgtype))
        listener = Listener(on_data_available=on_data)
        self._readers[topic] = DataReader(self.dp, dds, qos=qos(), listener=listener)

    def subscribed(self) -> set:
        """The ROS topics with a reader so far."""
        return {t for t, r in self._readers.items() if r is not None}

    def _take(self, timeout: float) -> list:
        try:
            items = [self._queue.get(timeout=timeout)]
        except queue.Empty:
            return []
        while True:
            try:
                items.append(self._queue.get_nowait())
            except queue.Empty:
                self.received += len(items)
                return items


class Ros2Source(_Readers):
    """The mapped topics of a topics file, subscribed as their publishers appear."""

    def __init__(self, topics: TopicsFile, converter: LiveTopics | None = None, dp=None):
        from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication

        super().__init__(dp)
        self.topics = topics
        self.converter = converter or LiveTopics(topics)
        self.skips = self.converter.skips
        self._pubs = BuiltinDataReader(self.dp, BuiltinTopicDcpsPublication)
        self._wanted = {dds_topic(t): t for t in topics.topics}

    def _discover(self) -> None:
        for ep in self._pubs.take(N=256):
            topic = self._wanted.get(ep.topic_name)
            if topic is None or topic in self._readers:
                continue
            msgtype = ros_type(ep.type_name)
            m = self.topics.topics[topic]
            if msgtype not in MESSAGE_TYPES[m.table]:
                self.skips.add(
                    "wrong_type",
                    f"ros2: topic '{topic}': its publisher's type {ep.type_name} cannot fill "
                    f"table '{m.table}' (takes {', '.join(MESSAGE_TYPES[m.table])})",
                )
                self._readers[topic] = None
                continue
            self._subscribe(topic, msgtype)

    def poll(self, timeout: float = 0.05) -> list[tuple[float, str, str, dict]]:
        """(receive time [perf_counter s], robot, table, row) of the messages received since
        the last call; waits up to `timeout` s for the first."""
        self._discover()
        out = []
        for now, topic, msgtype, sample in self._take(timeout):
            msg = as_message(msgtype, sample)
            out += [(now, *r) for r in self.converter.rows(topic, msgtype, msg)]
        return out


def log_row_topic(robot: str, table: str) -> str:
    """The ROS 2 topic of one table of a log published as lines (`LOG_ROW`)."""
    return f"/graphloc/log/{robot}/{table}"


class Ros2LogSource(_Readers):
    """A log's tables (its manifest) published line by line as `graphloc_msgs/msg/LogRow`
    (`log_row_topic`), for rows no ROS message holds (MRCLAM's): each line split into its table's
    columns here (a wrong field count a `field_count` skip), its fields checked by the team it is
    pushed to."""

    def __init__(self, root, dp=None):
        from graphloc.textio import SkipReport
        from graphloc.records import columns
        from graphloc.io import is_tum
        from graphloc.manifest import read_manifest

        super().__init__(dp)
        self.manifest = read_manifest(root)
        self.skips = SkipReport()
        self._tables = {}  # topic -> (robot, table, its columns)
        for r in self.manifest.robots:
            for table, rel in r.tables.items():
                if is_tum(rel) or table == "groundtruth":  # no measurement
                    continue
                topic = log_row_topic(r.name, table)
                self._tables[topic] = (r.name, table, tuple(columns(table)))
                self._subscribe(topic, LOG_ROW)
        self._lines = dict.fromkeys(self._tables, 1)  # the header is line 1

    def poll(self, timeout: float = 0.05) -> list[tuple[float, str, str, dict]]:
        out = []
        for now, topic, _, sample in self._take(timeout):
            robot, table, cols = self._tables[topic]
            self._lines[topic] += 1
            row = self._row(robot, table, cols, self._lines[topic], sample.line)
            if row is not None:
                out.append((now, robot, table, row))
        return out

    def _row(self, robot: str, table: str, cols: tuple, line: int, text: str) -> dict | None:
        """Line `line` of `table` as column -> text (and `line`); None for a blank or comment
        line and for one that does not split into the table's columns (counted)."""
        from graphloc.textio import csv_fields

        if not text.strip() or text.lstrip()[0] == "#":
            return None
        where = f"robot {robot!r}, table {table!r}, line {line}"
        if '"' in text or "\0" in text:
            try:
                fields = csv_fields(text, list(cols))
            except ValueError as exc:
                self.skips.add("field_too_long", f"{where}: {exc}")
                return None
        else:
            fields = text.split(",")
        if len(fields) != len(cols):
            self.skips.add(
                "field_count", f"{where}: expected {len(cols)} fields, got {len(fields)}"
            )
            return None
        return {"line": line, **dict(zip(cols, fields))}


def ros_covariance(pose, cov: np.ndarray) -> list:
    """The 36 values of a ROS pose covariance (x y z rx ry rz, frame `map`) of a gtsam.Pose3's
    6x6 covariance in GTSAM's tangent order (body frame): J C J^T with J = diag(R, R), as a
    body-frame perturbation moves the pose by R times it in the world."""
    R = pose.rotation().matrix()
    J = np.zeros((6, 6))
    J[:3, :3] = J[3:, 3:] = R
    c = np.asarray(cov, dtype=float)[np.ix_(_GTSAM_TO_ROS, _GTSAM_TO_ROS)]
    return (J @ c @ J.T).ravel().tolist()


class Ros2Sink:
    """Poses out: `/<robot>/pose`, `/<robot>/path`, `/tf` (see the module docstring)."""

    def __init__(self, robots, dp=None, path_period: float = 5.0):
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        self.dp = dp if dp is not None else participant()
        self.path_period = path_period
        self._writers = {}
        for robot in robots:
            for suffix, msgtype in (("pose", POSE_TYPE), ("path", PATH_TYPE)):
                name = dds_topic(f"/{robot}/{suffix}")
                self._writers[(robot, suffix)] = DataWriter(
                    self.dp,
                    Topic(self.dp, name, idl_type(msgtype)),
                    qos=qos(KEEP_POSES if suffix == "pose" else 1),
                )
        self._tf = DataWriter(
            self.dp, Topic(self.dp, dds_topic("/tf"), idl_type(TF_TYPE)), qos=qos(KEEP_POSES)
        )
        self._paths: dict = {r: [] for r in robots}
        self.published = 0
        # the paths (a message of every pose so far: serializing it takes long, ~40 us a
        # pose) go out from a thread of their own every path_period s, not in the update
        self._stop = threading.Event()
        self._path_thread = threading.Thread(target=self._path_loop, daemon=True)
        self._path_thread.start()

    def _path_loop(self) -> None:
        while not self._stop.wait(self.path_period):
            for robot in self._paths:
                self.publish_path(robot)

    def _header(self, t: float, frame: str = FRAME):
        return idl_type("std_msgs/msg/Header")(
            stamp=idl_type("builtin_interfaces/msg/Time")(**stamp_of(t)), frame_id=frame
        )

    def _pose(self, pose):
        q = pose.rotation().toQuaternion()
        p = pose.translation()
        return idl_type("geometry_msgs/msg/Pose")(
            position=idl_type("geometry_msgs/msg/Point")(x=p[0], y=p[1], z=p[2]),
            orientation=idl_type("geometry_msgs/msg/Quaternion")(
                x=q.x(), y=q.y(), z=q.z(), w=q.w()
            ),
        )

    def publish(self, poses: dict) -> None:
        """`poses`: robot -> (time, gtsam.Pose3, 6x6 covariance, GTSAM tangent order)."""
        transforms = []
        for robot, (t, pose, cov) in poses.items():
            msg = idl_type(POSE_TYPE)(
                header=self._header(t),
                pose=idl_type("geometry_msgs/msg/PoseWithCovariance")(
                    pose=self._pose(pose), covariance=ros_covariance(pose, cov)
                ),
            )
            self._writers[(robot, "pose")].write(msg)
            self.published += 1
            stamped = idl_type("geometry_msgs/msg/PoseStamped")(
                header=self._header(t), pose=msg.pose.pose
            )
            self._paths[robot].append(stamped)
            p, o = msg.pose.pose.position, msg.pose.pose.orientation
            transforms.append(
                idl_type("geometry_msgs/msg/TransformStamped")(
                    header=self._header(t),
                    child_frame_id=robot,
                    transform=idl_type("geometry_msgs/msg/Transform")(
                        translation=idl_type("geometry_msgs/msg/Vector3")(x=p.x, y=p.y, z=p.z),
                        rotation=o,
                    ),
                )
            )
        if transforms:
            self._tf.write(idl_type(TF_TYPE)(transforms=transforms))

    def publish_path(self, robot: str) -> None:
        """The robot's poses published so far as one nav_msgs/Path."""
        path = list(self._paths[robot])  # a snapshot: the update thread appends
        if path:
            self._writers[(robot, "path")].write(
                idl_type(PATH_TYPE)(header=path[-1].header, poses=path)
            )

    def flush(self) -> None:
        """Every robot's full path (at the end of a run); the path thread stops."""
        self._stop.set()
        self._path_thread.join()
        for robot in self._paths:
            self.publish_path(robot)
