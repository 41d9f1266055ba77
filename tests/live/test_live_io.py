"""Live sources (issue 50): a log directory being written, tailed line by line, and ROS 2
topics over Cyclone DDS on loopback, each giving the rows the log reader / `graphloc import`
give for the same data."""

from __future__ import annotations

import math
import shutil
import time
from dataclasses import fields

import numpy as np
import pytest

from graphloc.cli import main
from graphloc.records import columns
from graphloc.io import iter_records
from graphloc.manifest import read_manifest
from helpers_bags import REAL_BAG, REAL_ODOM, real_bag_topics


def _records(root) -> dict:
    """(robot, table) -> rows of the log (column -> value), as the log reader reads them."""
    from graphloc.records import TABLES

    table_of = {cls: t for t, cls in TABLES.items()}
    out: dict = {}
    for rec in iter_records(root):
        t = table_of[type(rec)]
        out.setdefault((rec.robot, t), []).append({c: getattr(rec, c) for c in columns(t)})
    return out


def _grouped(rows) -> dict:
    out: dict = {}
    for robot, table, row in rows:
        out.setdefault((robot, table), []).append({c: row[c] for c in columns(table)})
    return out


@pytest.fixture(scope="module")
def feng_log(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("feng")
    assert main(["simulate", "feng-probabilistic", "--out", str(tmp / "log")]) == 0
    return tmp / "log"


def test_tail_of_a_log_being_written(feng_log, tmp_path):
    """The logger writes the manifest, then each table in pieces that end mid-line, one table
    only after the others; the tail returns every complete row once, the partial line when it
    is completed, and all rows equal the log reader's. A bad line is a skip naming file, line
    and field; the rows after it still come."""
    from graphloc.live.tail import LogTail

    live = tmp_path / "live"
    live.mkdir()
    tail = LogTail(live)
    with pytest.raises(FileNotFoundError, match="manifest.json"):
        tail.wait_manifest(0.1)
    shutil.copy(feng_log / "manifest.json", live / "manifest.json")
    manifest = tail.wait_manifest(1.0)
    files = {
        (r.name, t): p for r in manifest.robots for t, p in r.tables.items() if p.endswith(".csv")
    }
    assert len(files) >= 2
    got = []
    late = sorted(files)[-1]  # this table's file appears only after the others are written
    for key, rel in sorted(files.items()):
        if key == late:
            continue
        text = (feng_log / rel).read_bytes()
        (live / rel).parent.mkdir(parents=True, exist_ok=True)
        cut = len(text) // 2 + 3  # mid-line (the rows are longer than 3 bytes)
        (live / rel).write_bytes(text[:cut])
        got += [r[1:] for r in tail.poll()]
        n_lines = text[:cut].count(b"\n")
        assert len([g for g in got if g[:2] == key]) == n_lines - 1  # header, partial left
        with open(live / rel, "ab") as fh:
            fh.write(text[cut:])
        got += [r[1:] for r in tail.poll()]
    assert tail.poll() == []
    rel = files[late]
    (live / rel).parent.mkdir(parents=True, exist_ok=True)
    lines = (feng_log / rel).read_text().splitlines(keepends=True)
    bad = lines[1].split(",")
    bad[0] = "nan"
    (live / rel).write_text(lines[0] + ",".join(bad) + "".join(lines[1:]))
    got += [r[1:] for r in tail.poll()]
    assert tail.skips.counts == {"non_finite": 1}
    assert f"{live / rel}: line 2: field 'time'" in tail.skips.examples[0]
    want = _records(feng_log)
    assert _grouped(got) == want
    assert tail.rows_read == sum(map(len, want.values()))


def _receive(source, expected: int, timeout: float = 30.0) -> list:
    rows, end = [], time.monotonic() + timeout
    while source.received < expected and time.monotonic() < end:
        rows += [r[1:] for r in source.poll(0.05)]
    return rows


def _same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        assert len(a[key]) == len(b[key]), key
        for x, y in zip(a[key], b[key]):
            for c, v in x.items():
                if isinstance(v, str):
                    assert v == y[c], (key, c)
                else:
                    assert math.isclose(v, y[c], rel_tol=0, abs_tol=1e-12), (key, c, v, y[c])


@pytest.mark.parametrize("bag", ["husky", "feng-mcap"])
def test_ros2_topics_give_the_import_rows(bag, loopback, feng_log, tmp_path):
    """A bag's messages published over DDS (ROS 2 names and types; the ROS 1 Husky bag's
    Odometry, a simulated run's PoseWithCovarianceStamped and vision_msgs Detection2DArray in
    MCAP) and received by `Ros2Source` give the rows `graphloc import` writes for that bag (in
    time order, as the bag is published in order)."""
    import yaml

    from graphloc.datasets.rosbag import import_bag
    from graphloc.datasets.rosbag_topics import read_topics
    from benchmarks.live_publish import Publisher, bag_messages
    from graphloc.live.ros2 import Ros2Source

    if bag == "husky":
        path, topics = REAL_BAG, tmp_path / "topics.yaml"
        topics.write_text(yaml.safe_dump(_husky_topics()))
    else:
        from benchmarks.rosbag_export import export_bag

        path = tmp_path / "bag"
        topics = export_bag(feng_log, path, "mcap")
    tf = read_topics(topics)
    imported = import_bag(path, tf, tmp_path / "imported")
    want = _records(imported.root)
    messages = bag_messages(path, set(tf.topics))
    source = Ros2Source(tf)
    pub = Publisher(messages)
    assert pub.wait_for_subscribers(0.2) == set(pub.writers)  # subscribed on discovery only
    end = time.monotonic() + 20
    while source.subscribed() != set(pub.writers) and time.monotonic() < end:
        source.poll(0.05)
    assert pub.wait_for_subscribers(10.0) == set()
    pub.run(rate=None)
    rows = _receive(source, len(messages))
    assert source.received == len(messages)
    truth = [r for r in rows if r[1] == "groundtruth"]
    got = _grouped([r for r in rows if r[1] != "groundtruth"])
    for key in got:  # the import sorts each table by time; one bag topic per table here
        got[key].sort(key=lambda r: r["time"])
    _same(got, want)
    assert source.converter.skips.total == imported.skips.total == 0
    tum = {r.name: r.tables.get("groundtruth") for r in read_manifest(imported.root).robots}
    for robot, rel in tum.items():  # ground truth: a TUM line per message, the same poses
        mine = np.array([list(r[2].values()) for r in truth if r[0] == robot]).reshape(-1, 8)
        theirs = np.loadtxt(imported.root / rel, ndmin=2) if rel else np.zeros((0, 8))
        mine = mine[np.argsort(mine[:, 0], kind="stable")]
        sign = np.sign(np.sum(mine[:, 4:] * theirs[:, 4:], axis=1))[:, None]  # q, -q: one pose
        mine[:, 4:] *= sign
        np.testing.assert_allclose(mine, theirs, atol=1e-9)


def _husky_topics() -> dict:
    from rosbags.highlevel import AnyReader

    with AnyReader([REAL_BAG]) as reader:
        conn = next(c for c in reader.connections if c.topic == REAL_ODOM)
        _, _, raw = next(reader.messages(connections=[conn]))
        p = reader.deserialize(raw, conn.msgtype).pose.pose
    first = [p.position.x, p.position.y, p.position.z]
    first += [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]
    return real_bag_topics(first)


def test_received_poses_out(loopback):
    """`Ros2Sink` publishes a pose with its covariance (GTSAM tangent order, body frame) as a
    PoseWithCovarianceStamped whose covariance is the same uncertainty in ROS's order in the
    map frame; a reader on the topic gets it back."""
    import gtsam
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from graphloc.live.ros2 import POSE_TYPE, Ros2Sink, participant, qos
    from graphloc.live.ros2_types import dds_topic, idl_type

    dp = participant()
    reader = DataReader(dp, Topic(dp, dds_topic("/r1/pose"), idl_type(POSE_TYPE)), qos=qos())
    sink = Ros2Sink(["r1"], dp=participant())
    pose = gtsam.Pose3(gtsam.Rot3.Ypr(0.7, 0.1, -0.2), gtsam.Point3(1.0, 2.0, 3.0))
    rng = np.random.default_rng(5)
    a = rng.standard_normal((6, 6))
    cov = a @ a.T + np.eye(6)
    end = time.monotonic() + 10
    while not sink._writers[("r1", "pose")].get_matched_subscriptions():
        assert time.monotonic() < end
        time.sleep(0.05)
    sink.publish({"r1": (12.5, pose, cov)})
    got = []
    while not got and time.monotonic() < end:
        got = [s for s in reader.take(N=10) if hasattr(s, "header")]
        time.sleep(0.02)
    (msg,) = got
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == (
        12,
        500_000_000,
        "map",
    )
    p = msg.pose.pose.position
    np.testing.assert_allclose([p.x, p.y, p.z], [1.0, 2.0, 3.0])
    # a world-frame position sample: R times the body-frame translation perturbation
    R = pose.rotation().matrix()
    ros = np.asarray(msg.pose.covariance).reshape(6, 6)
    np.testing.assert_allclose(ros[:3, :3], R @ cov[3:, 3:] @ R.T, atol=1e-12)
    np.testing.assert_allclose(ros[3:, 3:], R @ cov[:3, :3] @ R.T, atol=1e-12)
    np.testing.assert_allclose(ros[:3, 3:], R @ cov[3:, :3] @ R.T, atol=1e-12)


def test_live_view_logs_poses_and_ellipsoids(tmp_path):
    """The Foxglove view's server starts on a free port; what it logs (recorded by an MCAP
    sink on its context) is each robot's pose, its path, tf and a SceneUpdate whose ellipsoid
    diameters are twice the square roots of the position covariance's eigenvalues."""
    import foxglove
    import gtsam
    from mcap.reader import make_reader

    from graphloc.live.view import LiveView, position_ellipsoid

    view = LiveView(port=0)
    assert view.port > 0
    mcap = tmp_path / "view.mcap"
    writer = foxglove.open_mcap(str(mcap), context=view.context)
    pose = gtsam.Pose3(gtsam.Rot3.Ypr(0.5, 0.0, 0.0), gtsam.Point3(1.0, 2.0, 3.0))
    cov = np.diag([1e-4, 1e-4, 1e-4, 0.04, 0.01, 0.0025])
    view.show({"r1": (1.0, pose, cov), "r2": (0.9, pose, cov)}, 1.0)
    writer.close()
    view.close()
    with open(mcap, "rb") as fh:
        got = {(ch.topic, sch.name) for sch, ch, _ in make_reader(fh).iter_messages()}
    assert got == {
        ("/graphloc/r1/pose", "foxglove.PoseInFrame"),
        ("/graphloc/r2/pose", "foxglove.PoseInFrame"),
        ("/graphloc/r1/path", "foxglove.PosesInFrame"),
        ("/graphloc/r2/path", "foxglove.PosesInFrame"),
        ("/tf", "foxglove.FrameTransforms"),
        ("/graphloc/covariance", "foxglove.SceneUpdate"),
    }
    axes, rot = position_ellipsoid(pose, cov)
    np.testing.assert_allclose(sorted(axes), [0.05, 0.1, 0.2], atol=1e-12)
    R = pose.rotation().matrix()
    np.testing.assert_allclose(rot @ np.diag(axes**2) @ rot.T, R @ cov[3:, 3:] @ R.T, atol=1e-12)


def test_log_rows_over_ros2(loopback, feng_log, tmp_path):
    """A log published line by line (graphloc_msgs/msg/LogRow) and read by `Ros2LogSource`
    gives the log's lines split into their columns, as text (the log reader's rows once
    converted: the fields are checked by the team they are pushed to); a line of the wrong
    number of fields is a skip of the source naming robot, table and line, a bad field passes
    (the team's to count), and the lines after them still come."""
    from benchmarks.live_publish import Publisher, log_messages
    from graphloc.live.ros2 import Ros2LogSource
    from graphloc.records import TABLES

    log = tmp_path / "log"
    shutil.copytree(feng_log, log)
    messages = log_messages(log)
    robot, table = messages[0][1].split("/")[-2:]
    mine = [i for i, m in enumerate(messages) if m[1] == messages[0][1]]
    bad = "x" + messages[mine[0]][3].line  # the table's first data line: line 2 of its file
    messages[mine[0]][3].line = bad
    messages[mine[1]][3].line += ",1"  # line 3: one field too many
    source = Ros2LogSource(log)
    pub = Publisher(messages)
    assert pub.wait_for_subscribers(10.0) == set()
    pub.run(rate=None)
    rows = _receive(source, len(messages))
    assert source.received == len(messages)
    assert source.skips.counts == {"field_count": 1}
    assert f"robot {robot!r}, table {table!r}, line 3: expected" in source.skips.examples[0]
    first = next(row for r, t, row in rows if (r, t) == (robot, table))
    assert first["line"] == 2 and first["time"] == bad.split(",")[0]
    want = _records(feng_log)
    want[(robot, table)] = want[(robot, table)][2:]
    kinds = {t: {f.name: f.type for f in fields(TABLES[t])} for t in {t for _, t, _ in rows}}
    typed = [
        (r, t, {c: v if kinds[t][c] in (str, "str") else float(v) for c, v in row.items()})
        for r, t, row in rows
        if row["line"] != 2 or (r, t) != (robot, table)
    ]
    _same(_grouped(typed), want)


def test_log_rows_over_ros2_are_checked_once(loopback, planar_log, tmp_path):
    """A live log's lines over ROS 2 pushed into a team: a line with a bad field is one counted
    skip, the team's, naming robot, table and field (the source passes it on unchecked), and
    the team's estimates are those of the log replayed (whose reader skips that line)."""
    from graphloc.live import LiveTeam, replay_live
    from benchmarks.live_publish import Publisher, log_messages
    from graphloc.live.ros2 import Ros2LogSource

    log = tmp_path / "log"
    shutil.copytree(planar_log, log)
    manifest = read_manifest(log)
    robot = manifest.robots[0]
    path = log / robot.tables["odometry"]
    lines = path.read_text().splitlines()
    lines[5] = "x" + lines[5]  # line 6 of the file
    path.write_text("\n".join(lines) + "\n")
    messages = log_messages(log)
    source = Ros2LogSource(log)
    pub = Publisher(messages)
    assert pub.wait_for_subscribers(10.0) == set()
    pub.run(rate=None)
    rows = _receive(source, len(messages))
    assert source.skips.total == 0
    team = LiveTeam.open(log, window=0.5)
    for r, t, row in rows:  # arrival order: the publisher's, time order
        team.push(r, t, row)
    assert team.skips.counts == {"parse": 1}
    assert f"robot {robot.name!r}, table 'odometry', row " in team.skips.examples[0]
    assert "field 'time'" in team.skips.examples[0]
    reference = replay_live(log, window=0.5)
    result, want = team.finish(), reference.finish()
    assert len(result.estimate) == len(want.estimate)
    for a, b in zip(result.estimate, want.estimate):
        assert a.shape == b.shape and np.allclose(a, b, rtol=0, atol=1e-9, equal_nan=True)


def test_odometry_table_from_twists(tmp_path):
    """A topics file maps nav_msgs/Odometry (or TwistStamped) to the `odometry` table: one row
    per message, v = twist.linear.x and omega = twist.angular.z, at the header stamps."""
    import yaml
    from rosbags.highlevel import AnyReader

    from graphloc.datasets.rosbag import import_bag

    topics = tmp_path / "topics.yaml"
    body = _husky_topics()
    body["topics"] = {REAL_ODOM: {"robot": "husky", "table": "odometry", "sensor": "wheels"}}
    topics.write_text(yaml.safe_dump(body))
    result = import_bag(REAL_BAG, topics, tmp_path / "log")
    assert result.rows == {"odometry": 1200} and result.skips.total == 0
    want = []
    with AnyReader([REAL_BAG]) as reader:
        conns = [c for c in reader.connections if c.topic == REAL_ODOM]
        for conn, _, raw in reader.messages(connections=conns):
            m = reader.deserialize(raw, conn.msgtype)
            t = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
            want.append((t, m.twist.twist.linear.x, m.twist.twist.angular.z))
    got = np.loadtxt(
        tmp_path / "log/husky/odometry.csv", delimiter=",", skiprows=1, usecols=(0, 2, 3)
    )
    np.testing.assert_array_equal(got, np.array(sorted(want)))


def test_recorder_writes_a_log_and_resumes_it(tmp_path):
    """A live ROS 2 run's rows written as a log directory (the import's manifest and paths):
    the log reader reads them back as written; opened again it is continued (new rows
    appended), and a log of another topics file is refused, naming it."""
    import yaml

    from graphloc.datasets.rosbag_topics import read_topics
    from graphloc.live.record import LogRecorder

    body = _husky_topics()
    body["topics"] = {REAL_ODOM: {"robot": "husky", "table": "odometry", "sensor": "wheels"}}
    topics = tmp_path / "topics.yaml"
    topics.write_text(yaml.safe_dump(body))
    tf = read_topics(topics)
    rows = [
        (
            "husky",
            "odometry",
            {"time": 10.0 + k / 3, "sensor": "wheels", "v": 0.1 * k, "omega": -0.01},
        )
        for k in range(5)
    ]
    rec = LogRecorder(tf, tmp_path / "log")
    assert not rec.resumed
    rec.write(rows[:3])
    rec.close()
    again = LogRecorder(tf, tmp_path / "log")
    assert again.resumed
    again.write(rows[3:])
    again.close()
    assert _grouped(
        [("husky", "odometry", r) for r in _records(tmp_path / "log")[("husky", "odometry")]]
    ) == _grouped(rows)
    body["topics"][REAL_ODOM]["table"] = "relative_pose3"
    topics.write_text(yaml.safe_dump(body))
    with pytest.raises(ValueError, match="a log of other topics"):
        LogRecorder(read_topics(topics), tmp_path / "log")


def test_a_publisher_of_the_wrong_type_is_a_counted_skip(loopback, tmp_path):
    """A mapped topic whose publisher announces a type its table does not take (a Range on an
    odometry topic) is not read: one `wrong_type` skip naming the topic and both types."""
    import yaml

    from graphloc.datasets.rosbag_topics import read_topics
    from benchmarks.live_publish import Publisher
    from graphloc.live.ros2 import Ros2Source
    from graphloc.live.ros2_types import idl_type

    topics = tmp_path / "topics.yaml"
    topics.write_text(yaml.safe_dump(_husky_topics()))
    source = Ros2Source(read_topics(topics))
    head = idl_type("std_msgs/msg/Header")(
        stamp=idl_type("builtin_interfaces/msg/Time")(sec=1, nanosec=0), frame_id="uwb"
    )
    rng = idl_type("sensor_msgs/msg/Range")(
        header=head, radiation_type=0, field_of_view=0.1, min_range=0.1, max_range=9.0, range=2.0
    )
    pub = Publisher([(0.0, REAL_ODOM, "sensor_msgs/msg/Range", rng)])
    end = time.monotonic() + 10
    while not source.skips.total and time.monotonic() < end:
        assert source.poll(0.05) == []
    assert source.skips.counts == {"wrong_type": 1}
    assert f"topic '{REAL_ODOM}'" in source.skips.examples[0]
    assert "sensor_msgs::msg::dds_::Range_" in source.skips.examples[0]
    assert source.subscribed() == set() and pub.wait_for_subscribers(0.5) == {REAL_ODOM}
