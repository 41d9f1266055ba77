"""A bag's or a log's messages published as ROS 2 topics over Cyclone DDS, for
`scripts/publish_bag_ros2.py`, the loopback test and the live benchmark: the topics a topics
file maps, in bag order, at their recorded rate (`rate` 1.0), faster, or as fast as they go
(`rate` None). Each message is copied into its ROS 2 DDS type by field name
(`to_idl`), so a ROS 1 bag's messages go out as their ROS 2 types."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from graphloc.live.ros2 import participant, qos
from graphloc.live.ros2_types import dds_topic, idl_type, typestore


def bag_messages(bag, topics: set) -> list[tuple[float, str, str, object]]:
    """(bag time [s], topic, ROS 2 msgtype, DDS sample) of the bag's messages on `topics`, in
    bag order; ValueError naming the bag when it cannot be read."""
    from rosbags.highlevel import AnyReader

    from graphloc.datasets.rosbag import bag_typestore

    bag = Path(bag)
    out = []
    try:
        with AnyReader([bag], default_typestore=bag_typestore(bag)) as reader:
            conns = [c for c in reader.connections if c.topic in topics]
            for conn, t_ns, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                out.append((t_ns * 1e-9, conn.topic, conn.msgtype, to_idl(msg, conn.msgtype)))
    except (OSError, KeyError) as exc:
        raise ValueError(f"{bag}: cannot read bag: {type(exc).__name__}: {exc}") from None
    return out


def log_messages(root) -> list[tuple[float, str, str, object]]:
    """(row time [s], topic, LOG_ROW, sample) of every data line of a log's measurement
    tables (ground truth, CSV or TUM, aside), merged by time (stable: robot, then table
    order), each line as its table's `graphloc_msgs/msg/LogRow` (`ros2.log_row_topic`)."""
    from graphloc.records import columns
    from graphloc.io import is_tum
    from graphloc.manifest import read_manifest
    from graphloc.live.ros2 import LOG_ROW, log_row_topic, stamp_of
    from graphloc.table_reader import data_lines

    manifest = read_manifest(root)
    Row, Header, Time = (
        idl_type(LOG_ROW),
        idl_type("std_msgs/msg/Header"),
        idl_type("builtin_interfaces/msg/Time"),
    )
    out = []
    for r in manifest.robots:
        for table, rel in r.tables.items():
            if is_tum(rel) or table == "groundtruth":
                continue
            topic, t = log_row_topic(r.name, table), 0.0
            for _, text in data_lines(manifest.root / rel, columns(table)):
                try:
                    t = float(text.split(",", 1)[0])
                except ValueError:  # a bad time: sent where it stands, the reader skips it
                    pass
                head = Header(stamp=Time(**stamp_of(max(t, 0.0))), frame_id="")
                out.append(
                    (t, topic, LOG_ROW, Row(header=head, robot=r.name, table=table, line=text))
                )
    out.sort(key=lambda m: m[0])
    return out


class Publisher:
    """One DDS writer per topic of `messages` (reliable, keep-all: `graphloc.live.ros2.qos`)."""

    def __init__(self, messages, dp=None):
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        self.dp = dp if dp is not None else participant()
        self.messages = messages
        self.writers = {}
        for _, topic, msgtype, _ in messages:
            if topic not in self.writers:
                dds = Topic(self.dp, dds_topic(topic), idl_type(msgtype))
                self.writers[topic] = DataWriter(self.dp, dds, qos=qos())

    def wait_for_subscribers(self, timeout: float) -> set:
        """Wait until every writer has a matched reader (at most `timeout` s): messages sent
        before a reader matches are not delivered to it (volatile durability). Returns the
        topics still without a reader."""
        end = time.monotonic() + timeout
        while True:
            alone = {t for t, w in self.writers.items() if not w.get_matched_subscriptions()}
            if not alone or time.monotonic() >= end:
                return alone
            time.sleep(0.05)

    def run(self, rate: float | None = 1.0, on_write=None) -> int:
        """Publish every message: at `rate` times the bag's pace (None: at once);
        `on_write(index, perf_counter time)` after each write. Returns the number written."""
        if rate is not None and not rate > 0:
            raise ValueError(f"--rate must be > 0, got {rate}")
        start = time.perf_counter()
        t0 = self.messages[0][0] if self.messages else 0.0
        for k, (t, topic, _, sample) in enumerate(self.messages):
            if rate is not None:
                delay = start + (t - t0) / rate - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
            self.writers[topic].write(sample)
            if on_write is not None:
                on_write(k, time.perf_counter())
        return len(self.messages)

    def drain(self, timeout: float = 10.0) -> None:
        """Wait until the readers acknowledged every message (reliable QoS)."""
        from cyclonedds.util import duration

        for w in self.writers.values():
            w.wait_for_acks(duration(seconds=timeout))


def _copy(value, node):
    kind, spec = node
    kind = int(kind)
    if kind == 1:
        return value.item() if isinstance(value, np.generic) else value
    if kind == 2:
        return to_idl(value, spec)
    inner, _ = spec
    if kind == 4 and int(inner[0]) == 1 and inner[1][0] in ("uint8", "byte", "char"):
        return np.asarray(value, dtype=np.uint8).tobytes()
    if int(inner[0]) == 1:
        return np.asarray(value).tolist() if isinstance(value, np.ndarray) else list(value)
    return [_copy(v, inner) for v in value]


def to_idl(msg, msgtype: str):
    """A rosbags message (either type store: a ROS 1 header's `seq` has no ROS 2 field and is
    left out) as the DDS sample of ROS 2 type `msgtype`."""
    fields = typestore().fielddefs[msgtype][1]
    return idl_type(msgtype)(**{n: _copy(getattr(msg, n), node) for n, node in fields})
