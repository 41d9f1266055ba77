"""ROS 1 / ROS 2 sqlite3 / MCAP bags (issue 18) through `rosbags`, no ROS installation:
`import_bag` writes a log directory (version 2) as the topics file maps it (docs/rosbag.md), the
`RosBag` loader imports into a temporary directory and reads that. A bad message is a counted
skip naming bag, topic and message index."""

from __future__ import annotations

import atexit
import copy
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.datasets.camera_track import stack_poses
from graphloc.datasets.graphloc_log import read_team_run
from graphloc.datasets.rosbag_messages import (
    Bad,
    camera_params,
    count_backwards,
    message_rows,
    pose_rows,
    tf_edges,
    tf_extrinsics,
)
from graphloc.datasets.rosbag_topics import (
    CAMERA_INFO,
    TF_MESSAGE,
    TF_TOPICS,
    TOPICS_FILE,
    TopicsFile,
    find_topics_file,
    read_topics,
)
from graphloc.eval import write_tum
from graphloc.textio import SkipReport
from graphloc.manifest import write_manifest
from graphloc.log_writer import write_csv, write_table
from graphloc.names import out_path
from graphloc.run import TeamRun, truncate

__all__ = ["BagImport", "RosBag", "find_topics_file", "import_bag", "is_bag", "read_topics"]


def is_bag(path) -> bool:
    """A ROS 1 `.bag` file, an `.mcap` file, or a ROS 2 bag directory (metadata.yaml)."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.is_file() and path.suffix in (".bag", ".mcap")


@dataclass
class BagImport:
    """What an import wrote: the log directory, rows per table, the counted skips, topics of
    the bag the topics file does not map, mapped topics the bag does not hold, and `notes`:
    what was used but is counted to be said (`stamp_backwards`: a message stamped before an
    earlier message of its topic, re-sorted by stamp)."""

    root: Path
    rows: dict
    skips: SkipReport
    unmapped: list
    missing: list
    notes: SkipReport = field(default_factory=SkipReport)


# vision_msgs 4 (ROS 2 Humble); rosbags' type stores lack vision_msgs, so the bag carries them
VISION_MSGS = {
    "vision_msgs/msg/Point2D": "float64 x\nfloat64 y\n",
    "vision_msgs/msg/Pose2D": "vision_msgs/Point2D position\nfloat64 theta\n",
    "vision_msgs/msg/BoundingBox2D": "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": "vision_msgs/ObjectHypothesis hypothesis\n"
    "geometry_msgs/PoseWithCovariance pose\n",
    "vision_msgs/msg/Detection2D": "std_msgs/Header header\n"
    "vision_msgs/ObjectHypothesisWithPose[] results\n"
    "vision_msgs/BoundingBox2D bbox\nstring id\n",
    "vision_msgs/msg/Detection2DArray": "std_msgs/Header header\n"
    "vision_msgs/Detection2D[] detections\n",
}


def typestore(kind: str):
    """rosbags' Noetic (ros1) or Humble type store with vision_msgs 4 registered: the one bags
    are written with (`graphloc.live.ros2_types`, `benchmarks/rosbag_export.py`)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.ROS2_HUMBLE)
    types = {}
    for name, text in VISION_MSGS.items():
        types.update(get_types_from_msg(text, name))
    ts.register(types)
    return ts


def bag_typestore(bag: Path):
    """The type store a bag is read with: rosbags' Noetic (a `.bag`) or Humble store."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if bag.suffix == ".bag" else Stores.ROS2_HUMBLE)


def _read_messages(bag: Path, wanted: set, skips: SkipReport, consume):
    """Decoded messages of the `wanted` topics that `consume(topic, index, msgtype, msg)` does
    not take (returns False): topic -> [(bag index, msgtype, msg)], bag order; the number of
    messages per wanted topic; the bag's other topics. Undecodable messages are counted
    skips."""
    from rosbags.highlevel import AnyReader

    default = bag_typestore(bag)
    per_topic: dict = {t: [] for t in wanted}
    try:
        reader = AnyReader([bag], default_typestore=default)
        reader.open()
    except Exception as exc:  # noqa: BLE001 -- a corrupt bag raises AssertionError, MemoryError, ...
        raise ValueError(f"{bag}: cannot read bag: {type(exc).__name__}: {exc}") from None
    try:
        # types the bag does not define (e.g. a ROS 2 sqlite3 bag without definitions)
        have = reader.typestore.fielddefs
        reader.typestore.register({k: v for k, v in default.fielddefs.items() if k not in have})
        unmapped = sorted({c.topic for c in reader.connections} - wanted)
        conns = [c for c in reader.connections if c.topic in wanted]
        index = {t: 0 for t in wanted}
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
                if not consume(conn.topic, i, conn.msgtype, msg):
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
    return per_topic, index, unmapped


def _camera_intrinsics(bag: Path, tf: TopicsFile, per_topic: dict) -> dict:
    """(robot, sensor) -> intrinsics from the first CameraInfo of each camera's `camera_info`
    topic; a camera whose CameraInfo topic holds none is an error naming both topics."""
    out = {}
    for m in tf.topics.values():
        if m.camera_info is None or (m.robot, m.sensor) in out:
            continue
        infos = per_topic.get(m.camera_info, [])
        if not infos:
            raise ValueError(
                f"{bag}: topic '{m.topic}' message 0: no {CAMERA_INFO} on topic "
                f"'{m.camera_info}' (field 'camera_info' of {tf.path}), so the camera "
                f"{m.robot}/{m.sensor} has no intrinsics"
            )
        i, msgtype, msg = infos[0]
        where = f"{bag}: topic '{m.camera_info}' message {i}"
        if msgtype != CAMERA_INFO:
            raise ValueError(f"{where}: {msgtype} is not a {CAMERA_INFO}")
        try:
            out[(m.robot, m.sensor)] = camera_params(msg)
        except (Bad, AttributeError) as exc:
            raise ValueError(f"{where}: {exc}") from None
    return out


def _extrinsics(bag: Path, tf: TopicsFile, per_topic: dict) -> dict:
    """(robot, sensor) -> body_T_sensor 4x4 from tf_static, then tf (`frames` of the topics
    file); a sensor frame no chain of transforms reaches is an error naming it."""
    if not tf.frames:
        return {}
    msgs = []
    for topic in TF_TOPICS:
        for i, msgtype, msg in per_topic.get(topic, []):
            if msgtype != TF_MESSAGE:
                raise ValueError(f"{bag}: topic '{topic}' message {i}: {msgtype} is not a tf")
            msgs.append(msg)
    try:
        edges = tf_edges(msgs)
    except Bad as exc:
        raise ValueError(f"{bag}: topics {', '.join(TF_TOPICS)}: {exc}") from None
    out = {}
    for robot, entry in tf.frames.items():
        for sensor, frame in entry["sensors"].items():
            try:
                out[(robot, sensor)] = tf_extrinsics(edges, entry["body"], frame)
            except KeyError as exc:
                raise ValueError(
                    f"{bag}: {tf.path}: frames['{robot}'].sensors['{sensor}']: {exc.args[0]} "
                    f"({len(edges)} transforms on {', '.join(TF_TOPICS)})"
                ) from None
    return out


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
    notes = SkipReport()
    aux = {m.camera_info for m in tf.topics.values() if m.camera_info}
    aux |= set(TF_TOPICS) if tf.frames else set()
    out.mkdir(parents=True, exist_ok=True)
    streamed: dict = {t: [] for t in tf.topics}  # topic -> [(stamp, bag index, k, row)]

    def consume(topic, i, msgtype, msg) -> bool:  # every table but relative_pose3, as it comes
        m = tf.topics.get(topic)
        if m is None or m.table == "relative_pose3":
            return False
        got = message_rows(f"{bag}: topic '{topic}'", m, i, msgtype, msg, skips)
        if m.table == "scans":
            got = [(t, s, write_scan(out, m.robot, s, i, pts)) for t, s, pts in got]
        streamed[topic] += [(row[0], i, k, row) for k, row in enumerate(got)]
        return True

    per_topic, counts, unmapped = _read_messages(bag, set(tf.topics) | aux, skips, consume)
    intrinsics = _camera_intrinsics(bag, tf, per_topic)
    extrinsics = _extrinsics(bag, tf, per_topic)
    rows: dict = {}  # (robot, table) -> [row tuple starting with time]
    missing = []
    for topic, m in tf.topics.items():
        if not counts[topic]:
            missing.append(topic)
            skips.add("missing_topic", f"{bag}: topic '{topic}' ({tf.path}) has no messages")
            continue
        if m.table == "relative_pose3":
            got = pose_rows(f"{bag}: topic '{topic}'", m, per_topic[topic], skips, notes)
        else:  # in header-stamp order, bag order breaking ties
            count_backwards(f"{bag}: topic '{topic}'", [s[:2] for s in streamed[topic]], notes)
            got = [row for *_, row in sorted(streamed[topic], key=lambda s: s[:3])]
        rows.setdefault((m.robot, m.table), []).extend(got)
    written = {}
    tables: dict = {}  # robot -> {table: path relative to out}
    for (robot, table), rs in sorted(rows.items()):
        if not rs:
            continue
        rs.sort(key=lambda row: row[0])
        rel = table_path(robot, table)
        _write_table(out_path(out, *rel.split("/")), table, rs)
        tables.setdefault(robot, {})[table] = rel
        written[table] = written.get(table, 0) + len(rs)
    meta = {"source": str(bag), "topics": str(tf.path), "skips": skips.as_dict()}
    write_log_manifest(tf, out, tables, {**meta, "notes": notes.as_dict()}, intrinsics, extrinsics)
    return BagImport(out, written, skips, unmapped, missing, notes)


def table_path(robot: str, table: str) -> str:
    """Where a topics file's (robot, table) is written in a log directory, relative to it."""
    return f"{robot}/{'groundtruth.tum' if table == 'groundtruth' else table + '.csv'}"


def write_log_manifest(
    tf: TopicsFile,
    out: Path,
    tables: dict,
    meta: dict,
    intrinsics=None,
    extrinsics=None,
    key: str = "import",
) -> None:
    """The manifest (and landmarks.csv) of a log directory of the topics file `tf`: its robots
    with `tables` (robot -> {table: relative path}), the cameras' intrinsics and the sensors'
    extrinsics found in the bag ((robot, sensor) -> params / 4x4), `meta` as `meta.<key>`
    (`import`: what the log reader counts as the import's skips; `live`: a live recording)."""
    intrinsics, extrinsics = intrinsics or {}, extrinsics or {}
    robots = []
    for r in copy.deepcopy(tf.robots):
        name = r["name"]
        for s in r.get("sensors", []):
            if (name, s.get("name")) in intrinsics:
                s["params"] = {**s.get("params", {}), **intrinsics[(name, s["name"])]}
            if (name, s.get("name")) in extrinsics:
                s["extrinsics"] = extrinsics[(name, s["name"])].tolist()
        robots.append({**r, "tables": dict(sorted(tables.get(name, {}).items()))})
    body = {
        "name": tf.name,
        "start_time": tf.start_time,
        "robots": robots,
        "meta": {**tf.meta, key: meta},
    }
    if tf.landmarks:
        header = ["id", "x", "y", "z", "sigma_x", "sigma_y", "sigma_z"]
        rows = [
            [lm["id"], *map(float, lm["xyz"]), *map(float, lm.get("sigma", [0, 0, 0]))]
            for lm in tf.landmarks
        ]
        write_csv(out_path(out, "landmarks.csv"), header, rows)
        body["landmarks"] = {"file": "landmarks.csv"}
    write_manifest(body, out)


def write_scan(out: Path, robot: str, sensor: str, index: int, pts: np.ndarray) -> str:
    """One cloud as ROBOT/scans/SENSOR_INDEX.ply (float64; INDEX: the message's index in its
    topic); returns the path relative to `out`, as the `scans` table holds it."""
    import open3d as o3d

    rel = f"{robot}/scans/{sensor}_{index:06d}.ply"
    path = out_path(out, robot, "scans", f"{sensor}_{index:06d}.ply")
    path.parent.mkdir(parents=True, exist_ok=True)
    cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(np.asarray(pts, dtype=np.float64)))
    if not o3d.t.io.write_point_cloud(str(path), cloud):
        raise OSError(f"{path}: cannot write the scan")
    return rel


def _write_table(path: Path, table: str, rows: list) -> None:
    if table != "groundtruth":
        write_table(path, table, rows)
        return
    a = np.asarray(rows, dtype=float)  # timestamp tx ty tz qx qy qz qw -> the one TUM writer
    path.parent.mkdir(parents=True, exist_ok=True)
    write_tum(path, a[:, 0], stack_poses(Rotation.from_quat(a[:, 4:8]).as_matrix(), a[:, 1:4]))


# ---- the loader (graphloc.datasets.loaders protocol) -----------------------------------------
class RosBag:
    """A ROS 1 / ROS 2 / MCAP bag with its topics file (`topics`: a path, else `topics.yaml`
    inside or beside the bag; docs/rosbag.md): imported into a temporary log directory and read
    by `graphloc.datasets.graphloc_log.read_team_run`."""

    name = "rosbag"
    expects = f"a .bag / .mcap file or a metadata.yaml directory, with {TOPICS_FILE}"
    options = ("topics",)

    def matches(self, path: Path) -> bool:
        return is_bag(path)

    def load(self, path: Path, duration: float | None, noise: dict | None, topics=None) -> TeamRun:
        topics = topics if topics is not None else find_topics_file(path)
        tmp = tempfile.mkdtemp(prefix="graphloc-bag-")
        run = None
        try:
            result = import_bag(path, topics, tmp)
            try:
                run = read_team_run(tmp, overrides=noise)
            except ValueError as exc:  # named by the bag, with what its import skipped
                skipped = ", ".join(f"{k} {n}" for k, n in sorted(result.skips.counts.items()))
                raise ValueError(
                    f"{str(exc).replace(tmp, f'{path} (imported)')} "
                    f"(import skipped: {skipped or 'nothing'})"
                ) from None
        finally:
            if run is None or not run.scans:
                shutil.rmtree(tmp, ignore_errors=True)
        if run.scans:  # the team graph reads scans again to register robots: kept until exit
            atexit.register(shutil.rmtree, tmp, ignore_errors=True)
        # the temporary tables' rows are named by the bag's import in messages
        run.skips.examples[:] = [m.replace(tmp, f"{path} (imported)") for m in run.skips.examples]
        return run if duration is None else truncate(run, duration)
