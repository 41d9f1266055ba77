"""ROS bags in (issue 18, bag-loader half; datasets/rosbag.py, docs/rosbag.md): a simulated
run (SE(3) odometry + UWB ranges to static beacons, ground truth) written once as a native log
directory and once as ROS 1, ROS 2 sqlite3 and MCAP bags with rosbags' writers; `graphloc
import` + `graphloc smooth` must give the native log's estimates; bad messages are counted
skips naming topic and message index; topics-file errors name the file and the field."""

from __future__ import annotations

import json
from pathlib import Path

import gtsam
import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from graphloc.cli import main
from graphloc.datasets import open_run
from graphloc.datasets.rosbag import import_bag, read_topics
from helpers_bags import (
    REAL_BAG,
    REAL_ODOM,
    real_bag_topics,
    BEACONS,
    N,
    TOPICS,
    _header,
    _msg,
    _pose_msg,
    simulate,
    stamp,
    write_bag,
    write_native,
)


def estimates(out: Path) -> dict:
    """Every TUM estimate smooth wrote: file name -> (F, 8) array."""
    return {p.name: np.loadtxt(p, ndmin=2) for p in sorted(out.rglob("*.tum"))}


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("native")
    sim = simulate()
    log = write_native(sim, tmp / "log")
    assert main(["smooth", str(log), "--out", str(tmp / "out"), "--no-progress"]) == 0
    metrics = json.loads((tmp / "out/metrics.json").read_text())
    return sim, estimates(tmp / "out"), metrics


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
def test_import_then_smooth_gives_the_native_estimates(kind, native, tmp_path):
    sim, want, metrics = native
    bag = write_bag(sim, tmp_path / ("run.bag" if kind == "ros1" else "run"), kind)
    (tmp_path / "topics.yaml").write_text(yaml.safe_dump(TOPICS))
    run = tmp_path / "imported"
    assert (
        main(["import", str(bag), "--topics", str(tmp_path / "topics.yaml"), "--out", str(run)])
        == 0
    )
    assert main(["smooth", str(run), "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    got = estimates(tmp_path / "out")
    assert want and got.keys() == want.keys()
    for name in want:
        assert np.abs(got[name] - want[name]).max() < 1e-9, name
    m = json.loads((tmp_path / "out/metrics.json").read_text())
    assert m["tables"] == metrics["tables"] and m["counts"] == metrics["counts"]
    rover, native_rover = m["per_robot"]["rover"], metrics["per_robot"]["rover"]
    assert abs(rover["batch"]["ate_rmse"] - native_rover["batch"]["ate_rmse"]) < 1e-9
    assert rover["batch"]["ate_rmse"] < 0.5 * rover["dead_reckoning"]["ate_rmse"]


def test_open_run_finds_topics_beside_the_bag_and_mcap_file(native, tmp_path):
    sim, want, _ = native
    bag = write_bag(sim, tmp_path / "run", "mcap")
    (tmp_path / "topics.yaml").write_text(yaml.safe_dump(TOPICS))
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:  # the bag order is not the header-stamp order
        conns = [c for c in reader.connections if c.topic == "/rover/odom"]
        stamps = [
            reader.deserialize(raw, c.msgtype).header.stamp.sec * 1e9
            + reader.deserialize(raw, c.msgtype).header.stamp.nanosec
            for c, _, raw in reader.messages(connections=conns)
        ]
    assert stamps != sorted(stamps)
    team = open_run(bag)
    assert team.contributions["range"] == N * len(BEACONS)
    assert team.contributions["relative_pose3"] == N - 1 and team.skips.total == 0
    mcap = next(bag.glob("*.mcap"))  # a bare MCAP file: topics.yaml is looked for beside it
    (bag / "topics.yaml").write_text(yaml.safe_dump(TOPICS))
    assert open_run(mcap, duration=5.0).contributions["range"] == N * len(BEACONS)
    # `graphloc smooth BAG` through open_run
    assert main(["smooth", str(bag), "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    got = estimates(tmp_path / "out")
    assert all(np.abs(got[n] - want[n]).max() < 1e-9 for n in want)
    assert main(["online", str(bag), "--out", str(tmp_path / "online"), "--no-progress"]) == 0


@pytest.mark.parametrize("kind", ["ros1", "sqlite3"])
def test_bad_messages_are_counted_skips_naming_topic_and_index(kind, native, tmp_path):
    sim = native[0]
    bag = write_bag(sim, tmp_path / ("run.bag" if kind == "ros1" else "run"), kind, bad=True)
    topics = json.loads(json.dumps(TOPICS))
    topics["robots"][0]["sensors"].append({"name": "cam", "type": "bearing"})
    topics["topics"]["/rover/bearing"] = {
        "robot": "rover",
        "table": "bearing",
        "sensor": "cam",
        "target": "b1",
    }
    topics["topics"]["/rover/look"] = {
        "robot": "rover",
        "table": "bearing",
        "sensor": "cam",
        "target": "b2",
    }
    topics["topics"]["/rover/absent"] = {
        "robot": "rover",
        "table": "bearing",
        "sensor": "cam",
        "target": "b3",
    }
    (tmp_path / "topics.yaml").write_text(yaml.safe_dump(topics))
    result = import_bag(bag, tmp_path / "topics.yaml", tmp_path / "log")
    counts = result.skips.counts
    assert counts == {
        "not_finite": 1,
        "out_of_range": 1,
        "wrong_type": 1,
        "bad_direction": 1,
        "undecodable": 1,
        "missing_topic": 1,
    }, result.skips.as_dict()
    assert result.unmapped == ["/chatter"]
    text = "\n".join(result.skips.examples)
    assert "topic '/rover/bearing' message 0" in text and "topic '/rover/look' message" in text
    assert result.rows["range"] == N * len(BEACONS)  # the good rows are all there
    team = open_run(tmp_path / "log")
    assert team.contributions["range"] == N * len(BEACONS)
    manifest = json.loads((tmp_path / "log/manifest.json").read_text())
    assert manifest["meta"]["import"]["skips"]["total"] == 6
    # the loader carries the import's skips into TeamRun.skips
    assert open_run(bag).skips.counts["wrong_type"] == 1


def test_topics_file_errors_name_file_and_field(tmp_path, capsys):
    def check(topics, *needles):
        path = tmp_path / "t.yaml"
        path.write_text(yaml.safe_dump(topics))
        with pytest.raises(ValueError) as err:
            read_topics(path)
        assert str(path) in str(err.value), err.value
        for needle in needles:
            assert needle in str(err.value), err.value

    bad = json.loads(json.dumps(TOPICS))
    bad["topics"]["/rover/odom"]["robot"] = "rovr"
    check(bad, "topics['/rover/odom']", "field 'robot'", "'rovr'")
    bad = json.loads(json.dumps(TOPICS))
    bad["topics"]["/rover/odom"]["table"] = "odometry3"
    check(bad, "field 'table'", "'odometry3'")
    bad = json.loads(json.dumps(TOPICS))
    bad["topics"]["/rover/uwb/b1"]["sensor"] = "odom"
    check(bad, "field 'sensor'", "'range'")
    bad = json.loads(json.dumps(TOPICS))
    bad["topics"]["/rover/uwb/b1"]["target"] = "b9"
    check(bad, "field 'target'", "'b9'")
    bad = json.loads(json.dumps(TOPICS))
    bad["robots"][1]["initial_pose"] = [1, 2]
    check(bad, "robots[1]", "field 'initial_pose'")
    # through the verb: exit 2 and one line naming file and field
    bad = json.loads(json.dumps(TOPICS))
    bad["topics"]["/rover/odom"]["robot"] = "rovr"
    (tmp_path / "t.yaml").write_text(yaml.safe_dump(bad))
    bag = write_bag(simulate(), tmp_path / "b.bag", "ros1")
    assert (
        main(
            ["import", str(bag), "--topics", str(tmp_path / "t.yaml"), "--out", str(tmp_path / "o")]
        )
        == 2
    )
    assert "t.yaml: topics['/rover/odom']: field 'robot'" in capsys.readouterr().err
    # no topics file beside the bag: open_run says where it looked and what to do
    with pytest.raises(FileNotFoundError, match="name one with --topics FILE"):
        open_run(bag)


def test_detection2d_array_becomes_marker_rows(tmp_path):
    from graphloc.datasets.rosbag import typestore

    ts = typestore("mcap")  # Humble + vision_msgs 4, which the bag then carries
    zero = np.zeros(36)
    pose = _msg(
        ts,
        "geometry_msgs/msg/PoseWithCovariance",
        pose=_pose_msg(ts, gtsam.Pose3()),
        covariance=zero,
    )

    def detection(k, cid, u, v):
        hyp = _msg(
            ts,
            "vision_msgs/msg/ObjectHypothesisWithPose",
            pose=pose,
            hypothesis=_msg(ts, "vision_msgs/msg/ObjectHypothesis", class_id=cid, score=0.9),
        )
        centre = _msg(
            ts,
            "vision_msgs/msg/Pose2D",
            theta=0.0,
            position=_msg(ts, "vision_msgs/msg/Point2D", x=u, y=v),
        )
        box = _msg(ts, "vision_msgs/msg/BoundingBox2D", center=centre, size_x=4.0, size_y=4.0)
        return _msg(
            ts,
            "vision_msgs/msg/Detection2D",
            header=_header(ts, k, False),
            id="",
            results=[hyp],
            bbox=box,
        )

    name = "vision_msgs/msg/Detection2DArray"
    bag = tmp_path / "cam.mcap.d"
    with Writer2(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/cam/leds", name, typestore=ts)
        for k in (1, 0):  # recorded out of stamp order
            dets = [detection(k, f"led{i}", 100.0 + 10 * i + k, 200.0 - i) for i in range(3)]
            dets.append(detection(k, "led9", 1.0, 1.0))  # a class the topics file does not map
            msg = _msg(ts, name, header=_header(ts, k, False), detections=dets)
            writer.write(conn, int(stamp(k)[2] * 1e9), ts.serialize_cdr(msg, name))
    camera = {"fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480}
    topics = {
        "robots": [
            {
                "name": "climber",
                "kind": "ceiling",
                "planar": False,
                "initial_pose": [0, 0, 3, 1, 0, 0, 0],
                "sensors": [{"name": "camera", "type": "camera", "params": camera}],
            },
            {
                "name": "ground",
                "kind": "ground",
                "static": True,
                "initial_pose": [0, 0, 0],
                "markers": [[0.2, 0, 0.3], [-0.1, 0.2, 0.3], [-0.1, -0.2, 0.3]],
            },
        ],
        "topics": {
            "/cam/leds": {
                "robot": "climber",
                "table": "markers",
                "sensor": "camera",
                "classes": {f"led{i}": ["ground", i] for i in range(3)},
            }
        },
    }
    (tmp_path / "topics.yaml").write_text(yaml.safe_dump(topics))
    result = import_bag(bag, tmp_path / "topics.yaml", tmp_path / "log")
    assert result.rows == {"markers": 6} and result.skips.counts == {"bad_detection": 2}
    assert "class id 'led9'" in result.skips.examples[0]
    lines = (tmp_path / "log/climber/markers.csv").read_text().splitlines()
    assert lines[0] == "time,sensor,target,marker,u,v"
    assert lines[1] == f"{stamp(0)[2]!r},camera,ground,0,100.0,200.0"
    assert lines[6] == f"{stamp(1)[2]!r},camera,ground,2,121.0,198.0"


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
def test_truncated_bag_is_a_clear_error(kind, tmp_path, capsys):
    bag = write_bag(simulate(), tmp_path / ("run.bag" if kind == "ros1" else "run"), kind)
    storage = bag if kind == "ros1" else next(p for p in bag.iterdir() if p.suffix != ".yaml")
    data = storage.read_bytes()
    storage.write_bytes(data[: len(data) // 2])
    (tmp_path / "topics.yaml").write_text(yaml.safe_dump(TOPICS))
    assert main(["import", str(bag), "--out", str(tmp_path / "log")]) == 2
    err = capsys.readouterr().err
    assert f"graphloc import: error: {bag}: cannot read bag:" in err, err


# ---- scans, images + CameraInfo, tf_static (datasets/rosbag_messages.py) ---------------------
LEDS = np.array([[100.0, 120.0], [300.5, 110.25], [210.0, 330.0], [420.75, 260.5]])
LIDAR_T = gtsam.Pose3(gtsam.Rot3.Ypr(0.3, 0.0, 0.0), gtsam.Point3(0.1, 0.0, 0.2))
MOUNT_T = gtsam.Pose3(gtsam.Rot3(), gtsam.Point3(0.0, 0.05, 0.1))
OPTICAL_T = gtsam.Pose3(gtsam.Rot3.Ypr(-np.pi / 2, 0.0, -np.pi / 2), gtsam.Point3(0, 0, 0))


def _transform_msg(ts, parent, child, pose: gtsam.Pose3):
    q, t = pose.rotation().toQuaternion(), pose.translation()
    return _msg(
        ts,
        "geometry_msgs/msg/TransformStamped",
        header=_header(ts, 0, False, parent),
        child_frame_id=child,
        transform=_msg(
            ts,
            "geometry_msgs/msg/Transform",
            translation=_msg(ts, "geometry_msgs/msg/Vector3", x=t[0], y=t[1], z=t[2]),
            rotation=_msg(ts, "geometry_msgs/msg/Quaternion", x=q.x(), y=q.y(), z=q.z(), w=q.w()),
        ),
    )


def _cloud_msg(ts, k, pts):
    fields = [
        _msg(ts, "sensor_msgs/msg/PointField", name=n, offset=4 * i, datatype=7, count=1)
        for i, n in enumerate("xyz")
    ]
    data = np.frombuffer(np.asarray(pts, dtype="<f4").tobytes(), dtype=np.uint8)
    return _msg(
        ts,
        "sensor_msgs/msg/PointCloud2",
        header=_header(ts, k, False, "lidar_link"),
        height=1,
        width=len(pts),
        fields=fields,
        is_bigendian=False,
        point_step=12,
        row_step=12 * len(pts),
        data=data,
        is_dense=False,
    )


def _image_msg(ts, k):
    import cv2

    img = np.full((480, 640), 12, np.uint8)
    for u, v in LEDS:  # anti-aliased disks at sub-pixel centres (4 fractional bits)
        cv2.circle(img, (int(round(u * 16)), int(round(v * 16))), 6 * 16, 250, -1, cv2.LINE_AA, 4)
    return _msg(
        ts,
        "sensor_msgs/msg/Image",
        header=_header(ts, k, False, "cam_optical"),
        height=480,
        width=640,
        encoding="mono8",
        is_bigendian=0,
        step=640,
        data=img.ravel(),
    )


def _camera_info_msg(ts, k):
    roi = _msg(
        ts,
        "sensor_msgs/msg/RegionOfInterest",
        x_offset=0,
        y_offset=0,
        height=0,
        width=0,
        do_rectify=False,
    )
    return _msg(
        ts,
        "sensor_msgs/msg/CameraInfo",
        header=_header(ts, k, False, "cam_optical"),
        height=480,
        width=640,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=np.array([500.0, 0, 320.0, 0, 505.0, 240.0, 0, 0, 1]),
        r=np.eye(3).ravel(),
        p=np.zeros(12),
        binning_x=0,
        binning_y=0,
        roi=roi,
    )


SENSOR_TOPICS = {
    "robots": [
        {
            "name": "climber",
            "kind": "ceiling",
            "planar": False,
            "initial_pose": [0, 0, 3, 1, 0, 0, 0],
            "sensors": [
                {"name": "lidar", "type": "scanner"},
                {"name": "camera", "type": "camera", "params": {"pixel_sigma": 0.5}},
            ],
        },
        {
            "name": "ground",
            "kind": "ground",
            "static": True,
            "initial_pose": [0, 0, 0],
            "identical_markers": True,
            "markers": [[0.2, 0, 0.3], [-0.1, 0.2, 0.3], [-0.1, -0.2, 0.3], [0.0, 0.0, 0.5]],
        },
    ],
    "frames": {"climber": {"body": "base_link", "sensors": {"lidar": "lidar_link"}}},
    "topics": {
        "/lidar/points": {"robot": "climber", "table": "scans", "sensor": "lidar"},
        "/cam/image": {
            "robot": "climber",
            "table": "markers",
            "sensor": "camera",
            "target": "ground",
            "camera_info": "/cam/info",
        },
    },
}


def write_sensor_bag(path: Path, clouds: list) -> Path:
    """A ROS 2 MCAP bag: tf_static (base_link -> lidar_link, base_link -> cam_mount ->
    cam_optical), PointCloud2 scans, mono8 images of four LEDs and their CameraInfo."""
    ts = get_typestore(Stores.ROS2_HUMBLE)
    tf = "tf2_msgs/msg/TFMessage"
    statics = [
        _transform_msg(ts, "base_link", "lidar_link", LIDAR_T),
        _transform_msg(ts, "base_link", "cam_mount", MOUNT_T),
        _transform_msg(ts, "cam_mount", "cam_optical", OPTICAL_T),
    ]
    with Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        c_tf = writer.add_connection("/tf_static", tf, typestore=ts)
        c_pc = writer.add_connection("/lidar/points", "sensor_msgs/msg/PointCloud2", typestore=ts)
        c_im = writer.add_connection("/cam/image", "sensor_msgs/msg/Image", typestore=ts)
        c_ci = writer.add_connection("/cam/info", "sensor_msgs/msg/CameraInfo", typestore=ts)
        t0 = int(stamp(0)[2] * 1e9)
        writer.write(c_tf, t0, ts.serialize_cdr(_msg(ts, tf, transforms=statics), tf))
        for k, pts in enumerate(clouds):
            t = int(stamp(k)[2] * 1e9) + 1000
            msg = _cloud_msg(ts, k, pts)
            writer.write(c_pc, t, ts.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2"))
            writer.write(c_im, t, ts.serialize_cdr(_image_msg(ts, k), "sensor_msgs/msg/Image"))
            info = _camera_info_msg(ts, k)
            writer.write(c_ci, t, ts.serialize_cdr(info, "sensor_msgs/msg/CameraInfo"))
    return path


def test_scans_images_camera_info_and_tf_static(tmp_path):
    from graphloc.mapping.io import read_points

    rng = np.random.default_rng(3)
    clouds = [rng.uniform(-5, 5, (200, 3)).astype(np.float32) for _ in range(3)]
    clouds[1][7] = np.nan  # a NaN return: dropped and counted
    bag = write_sensor_bag(tmp_path / "sensors", clouds)
    topics = json.loads(json.dumps(SENSOR_TOPICS))
    topics["frames"]["climber"]["sensors"]["camera"] = "cam_optical"
    (tmp_path / "topics.yaml").write_text(yaml.safe_dump(topics))
    result = import_bag(bag, tmp_path / "topics.yaml", tmp_path / "log")
    assert result.rows == {"scans": 3, "markers": 12}, result.skips.as_dict()
    assert result.skips.counts == {"nonfinite_points": 1}
    assert result.unmapped == []
    manifest = json.loads((tmp_path / "log/manifest.json").read_text())
    sensors = {s["name"]: s for s in manifest["robots"][0]["sensors"]}
    assert np.allclose(sensors["lidar"]["extrinsics"], LIDAR_T.matrix(), atol=1e-12)
    optical = MOUNT_T.compose(OPTICAL_T).matrix()
    assert np.allclose(sensors["camera"]["extrinsics"], optical, atol=1e-12)
    cam = sensors["camera"]["params"]
    assert (cam["fx"], cam["fy"], cam["cx"], cam["cy"], cam["pixel_sigma"]) == (
        500.0,
        505.0,
        320.0,
        240.0,
        0.5,
    )
    lines = (tmp_path / "log/climber/scans.csv").read_text().splitlines()
    assert lines[0] == "time,sensor,path" and len(lines) == 4
    for k, line in enumerate(lines[1:]):
        pts = read_points(tmp_path / "log" / line.split(",")[2])
        want = clouds[k][np.isfinite(clouds[k]).all(axis=1)]
        assert pts.shape == want.shape and np.abs(pts - want).max() < 1e-6
    marks = np.loadtxt(
        tmp_path / "log/climber/markers.csv", delimiter=",", skiprows=1, usecols=(0, 3, 4, 5)
    )
    assert len(marks) == 12
    for k in range(3):
        frame = marks[marks[:, 0] == stamp(k)[2]]
        assert sorted(frame[:, 1]) == [0, 1, 2, 3]
        got = frame[np.lexsort(frame[:, 2:4].T[::-1])][:, 2:4]
        want = LEDS[np.lexsort(LEDS.T[::-1])]
        assert np.abs(got - want).max() < 0.3, got


def test_missing_camera_info_and_unconnected_frames_are_errors(tmp_path, capsys):
    clouds = [np.random.default_rng(4).uniform(-5, 5, (50, 3)) for _ in range(2)]
    bag = write_sensor_bag(tmp_path / "sensors", clouds)
    topics = json.loads(json.dumps(SENSOR_TOPICS))
    topics["topics"]["/cam/image"]["camera_info"] = "/cam/camera_info"
    (tmp_path / "topics.yaml").write_text(yaml.safe_dump(topics))
    with pytest.raises(ValueError, match="topic '/cam/image' message 0: no sensor_msgs/msg/Camera"):
        import_bag(bag, tmp_path / "topics.yaml", tmp_path / "log")
    topics = json.loads(json.dumps(SENSOR_TOPICS))
    topics["frames"]["climber"]["sensors"]["lidar"] = "velodyne"
    (tmp_path / "topics.yaml").write_text(yaml.safe_dump(topics))
    assert main(["import", str(bag), "--out", str(tmp_path / "log2")]) == 2
    err = capsys.readouterr().err
    assert "frames['climber'].sensors['lidar']" in err and "'velodyne'" in err, err
    # the topics file's own errors: an image target without identical markers
    topics = json.loads(json.dumps(SENSOR_TOPICS))
    topics["robots"][1]["identical_markers"] = False
    (tmp_path / "topics.yaml").write_text(yaml.safe_dump(topics))
    with pytest.raises(ValueError, match=r"topics\['/cam/image'\]: field 'target'"):
        read_topics(tmp_path / "topics.yaml")


# ---- a real public bag ------------------------------------------------------------------------
# tests/data/real_bag/husky_outdoor_120s.bag: the first 120 s of robot_localization's
# test/test1.bag (BSD-3-Clause; tests/data/README.md, scripts/make_real_bag.py): a Clearpath
# Husky outdoors, wheel odometry (nav_msgs/Odometry with covariance), GPS fix and IMU:
# REAL_BAG, REAL_ODOM and real_bag_topics in tests/helpers_bags.py.


def _real_odometry() -> tuple[np.ndarray, np.ndarray]:
    """The odometry topic as the bag's messages say, read here with rosbags directly: TUM rows
    (header stamp, position, quaternion xyzw) in stamp order and the pose covariance diagonals
    (ROS order x y z rx ry rz)."""
    from rosbags.highlevel import AnyReader

    odom = []
    with AnyReader([REAL_BAG]) as reader:
        conns = [c for c in reader.connections if c.topic == REAL_ODOM]
        for conn, _, raw in reader.messages(connections=conns):
            m = reader.deserialize(raw, conn.msgtype)
            p, o = m.pose.pose.position, m.pose.pose.orientation
            t = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
            cov = np.diag(m.pose.covariance.reshape(6, 6))
            odom.append(([t, p.x, p.y, p.z, o.x, o.y, o.z, o.w], cov))
    odom.sort(key=lambda row: row[0][0])
    return np.array([r for r, _ in odom]), np.array([c for _, c in odom])


def test_real_bag_is_read_and_smoothed(tmp_path, capsys):
    """The Husky's wheel odometry with its covariance as one robot's relative poses, anchored at
    its first pose: `import` maps every odometry message (GPS and IMU reported as unmapped),
    and `smooth BAG --topics FILE` gives back the bag's odometry poses at their header stamps,
    each step weighted by the message's covariance."""
    odom, cov = _real_odometry()
    assert len(odom) > 1000 and np.ptp(odom[:, 1:3], axis=0).max() > 5.0  # a real drive
    topics = tmp_path / "husky_topics.yaml"  # not beside the bag: only --topics names it
    topics.write_text(yaml.safe_dump(real_bag_topics(odom[0, 1:])))
    run = tmp_path / "run"
    assert main(["import", str(REAL_BAG), "--topics", str(topics), "--out", str(run)]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["rows"] == {"relative_pose3": len(odom) - 1}
    assert printed["skipped"]["total"] == 0
    assert printed["unmapped_topics"] == ["/fix", "/imu/data"]
    rows = np.loadtxt(
        run / "husky/relative_pose3.csv", delimiter=",", skiprows=1, usecols=range(2, 16)
    )
    # sigmas: the message's covariance diagonal, ROS (x y z rx ry rz) -> GTSAM (rx ry rz x y z)
    np.testing.assert_allclose(rows[:, -6:], np.sqrt(cov[1:][:, [3, 4, 5, 0, 1, 2]]))
    out = tmp_path / "out"
    argv = ["smooth", str(REAL_BAG), "--topics", str(topics), "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    est = np.loadtxt(out / "husky_batch.tum", ndmin=2)
    np.testing.assert_allclose(est[:, 0], odom[:, 0], rtol=0, atol=1e-6)
    assert np.abs(est[:, 1:4] - odom[:, 1:4]).max() < 1e-6
    sign = np.sign(np.sum(est[:, 4:] * odom[:, 4:], axis=1))[:, None]  # q and -q: one rotation
    assert np.abs(est[:, 4:] * sign - odom[:, 4:]).max() < 1e-6
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["options"]["topics"] == str(topics)


def test_topics_option(tmp_path, capsys):
    """`--topics FILE` reaches the bag loader through RunOptions (command line and --config);
    without it and with no topics.yaml beside the bag the error says so; a bad topics file
    names the file and the field; a source that takes no topics file says so."""
    bag = tmp_path / "bag" / "real.bag"
    bag.parent.mkdir()
    bag.write_bytes(REAL_BAG.read_bytes())
    out = str(tmp_path / "out")
    assert main(["validate", str(bag)]) == 2
    assert "name one with --topics FILE" in capsys.readouterr().err
    topics = real_bag_topics([0, 0, 0, 0, 0, 0, 1])
    topics["topics"][REAL_ODOM]["robot"] = "huskyy"
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(topics))
    assert main(["smooth", str(bag), "--topics", str(bad), "--out", out, "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and f"topics['{REAL_ODOM}']: field 'robot'" in err, err
    good = tmp_path / "good.yaml"
    good.write_text(yaml.safe_dump(real_bag_topics([0, 0, 0, 0, 0, 0, 1])))
    config = tmp_path / "run.toml"
    config.write_text(f'topics = "{good}"\nduration = 10.0\n')
    assert main(["validate", str(bag), "--config", str(config)]) == 0
    report = json.loads(capsys.readouterr().out)
    stamps = _real_odometry()[0][:, 0]
    assert report["graph"]["factors_odometry"] == np.sum(stamps[1:] <= stamps[0] + 10.0)
    assert main(["validate", str(bag), "--topics", str(good), "--duration", "5"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["graph"]["factors_odometry"] == np.sum(stamps[1:] <= stamps[0] + 5.0)
    argv = ["online", str(bag), "--topics", str(good), "--duration", "5", "--out", out]
    assert main(argv + ["--no-progress"]) == 0
    online = np.loadtxt(tmp_path / "out/husky_online.tum", ndmin=2)
    assert len(online) == np.sum(stamps <= stamps[0] + 5.0)
    log = tmp_path / "log"
    import_bag(bag, good, log)
    assert main(["validate", str(log), "--topics", str(good)]) == 2
    assert "--topics does not apply to a graphloc-log source" in capsys.readouterr().err


# ---- round trip: every scenario as ROS 1, ROS 2 sqlite3 and MCAP bags ------------------------
SCENARIOS = (
    "feng-deterministic",
    "feng-probabilistic",
    "kaushik-p3p-error",
    "breitenmoser-target",
    "dual-robot-room",
)
ROUND_TRIPS = [
    pytest.param(
        name,
        kind,
        marks=()
        if name != "dual-robot-room" and (kind == "mcap" or name == "feng-probabilistic")
        else pytest.mark.slow,
    )
    for name in SCENARIOS
    for kind in ("ros1", "sqlite3", "mcap")
]


@pytest.fixture(scope="module")
def native_scenarios(tmp_path_factory):
    """scenario -> (log directory, smooth's TUM estimates), each simulated and smoothed once."""
    cache = {}

    def get(name):
        if name not in cache:
            tmp = tmp_path_factory.mktemp(name)
            assert main(["simulate", name, "--out", str(tmp / "log")]) == 0
            assert (
                main(["smooth", str(tmp / "log"), "--out", str(tmp / "out"), "--no-progress"]) == 0
            )
            cache[name] = (tmp / "log", estimates(tmp / "out"))
        return cache[name]

    return get


@pytest.mark.parametrize("name, kind", ROUND_TRIPS)
def test_scenario_round_trip_through_a_bag(name, kind, native_scenarios, tmp_path):
    from benchmarks.rosbag_export import export_bag

    log, want = native_scenarios(name)
    bag = tmp_path / ("b/run.bag" if kind == "ros1" else "bag")
    bag.parent.mkdir(exist_ok=True)
    export_bag(log, bag, kind)
    assert main(["smooth", str(bag), "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    got = estimates(tmp_path / "out")
    assert want and got.keys() == want.keys()
    assert any(n.endswith("_batch.tum") for n in want)
    for n in want:
        assert got[n].shape == want[n].shape and np.abs(got[n] - want[n]).max() < 1e-9, n
