"""The simulated UWB run of the bag tests (tests/datasets/test_rosbag.py, the `bag_dir`
fixture of tests/conftest.py): a rover's SE(3) odometry and ranges to three static beacons,
written as a native log directory and as ROS 1 / ROS 2 bags with rosbags' writers; and the
real Husky bag of tests/data."""

from __future__ import annotations

from pathlib import Path

import gtsam
import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from graphloc.records import columns
from graphloc.manifest import write_manifest

REAL_BAG = Path(__file__).resolve().parent / "data/real_bag/husky_outdoor_120s.bag"
# REAL_BAG's wheel odometry topic (nav_msgs/Odometry with covariance; tests/data/README.md)
REAL_ODOM = "/husky_velocity_controller/odom"


def real_bag_topics(first_pose) -> dict:
    """The topics file of REAL_BAG: one ground robot, its odometry as relative_pose3 rows,
    starting at `first_pose` (x, y, z, qx, qy, qz, qw)."""
    return {
        "name": "husky-outdoor",
        "robots": [
            {
                "name": "husky",
                "kind": "ground",
                "planar": False,
                "initial_pose": [float(v) for v in first_pose],
                "sensors": [{"name": "wheels", "type": "odometry"}],
            }
        ],
        "topics": {REAL_ODOM: {"robot": "husky", "table": "relative_pose3", "sensor": "wheels"}},
    }


T0, DT, N = 1700000000.0, 0.5, 30
SIGMAS = np.array([0.004, 0.004, 0.01, 0.02, 0.02, 0.01])  # GTSAM tangent order
BEACONS = {"b1": (4.0, 0.0, 2.0), "b2": (-3.0, 3.0, 2.5), "b3": (0.0, -4.0, 0.5)}
UWB_OFFSET = (0.1, 0.0, 0.3)
ROBOTS = [
    {
        "name": "rover",
        "kind": "ground",
        "planar": False,
        "initial_pose": [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        "sensors": [
            {"name": "odom", "type": "odometry"},
            {
                "name": "uwb",
                "type": "range",
                "extrinsics": {"xyz": list(UWB_OFFSET)},
                "params": {"range_sigma": 0.03, "range_sigma_per_m": 0.0},
            },
        ],
    },
    *[
        {"name": b, "kind": "beacon", "static": True, "initial_pose": [*xyz, 0, 0, 0, 1]}
        for b, xyz in BEACONS.items()
    ],
]


def stamp(k: int) -> tuple[int, int, float]:
    """(sec, nanosec, the float the bag reader makes of them) of step k."""
    t = T0 + DT * k
    sec = int(t)
    ns = round((t - sec) * 1e9)
    return sec, ns, sec + ns * 1e-9


def simulate(seed: int = 0) -> dict:
    """Ground truth, dead-reckoned odometry poses (their increments noisy by SIGMAS) and ranges
    (float32, as sensor_msgs/Range holds them) from the UWB antenna to each beacon."""
    rng = np.random.default_rng(seed)
    truth = []
    for k in range(N):
        a = 0.12 * k
        rot = gtsam.Rot3.Ypr(a, 0.02 * np.sin(a), 0.03 * np.sin(a))  # identity at k = 0
        truth.append(gtsam.Pose3(rot, gtsam.Point3(2 * np.cos(a), 2 * np.sin(a), 0.05 * k)))
    odo, steps = [truth[0]], []
    for k in range(1, N):
        step = (
            truth[k - 1]
            .between(truth[k])
            .compose(gtsam.Pose3.Expmap(SIGMAS * rng.standard_normal(6)))
        )
        steps.append(step)
        odo.append(odo[-1].compose(step))
    ranges = {b: [] for b in BEACONS}
    for k in range(N):
        antenna = truth[k].transformFrom(gtsam.Point3(*UWB_OFFSET))
        for b, xyz in BEACONS.items():
            r = np.linalg.norm(antenna - np.array(xyz)) + 0.03 * rng.standard_normal()
            ranges[b].append(float(np.float32(r)))
    return {"truth": truth, "odo": odo, "steps": steps, "ranges": ranges}


def tum_row(t, pose: gtsam.Pose3) -> str:
    q = pose.rotation().toQuaternion()
    return " ".join(repr(float(v)) for v in (t, *pose.translation(), q.x(), q.y(), q.z(), q.w()))


def write_native(sim: dict, root: Path) -> Path:
    """The run written directly as a log directory (docs/log_format.md)."""
    (root / "rover").mkdir(parents=True)
    rows = []
    for k in range(1, N):
        s = sim["steps"][k - 1]
        q = s.rotation().toQuaternion()
        rows.append(
            [
                stamp(k)[2],
                "odom",
                stamp(k - 1)[2],
                *s.translation(),
                q.x(),
                q.y(),
                q.z(),
                q.w(),
                *SIGMAS,
            ]
        )
    text = [",".join(columns("relative_pose3"))]
    text += [",".join(v if isinstance(v, str) else repr(float(v)) for v in r) for r in rows]
    (root / "rover/relative_pose3.csv").write_text("\n".join(text) + "\n")
    text = [",".join(columns("range"))]
    text += [f"{stamp(k)[2]!r},uwb,{b},{sim['ranges'][b][k]!r}" for k in range(N) for b in BEACONS]
    (root / "rover/range.csv").write_text("\n".join(text) + "\n")
    (root / "rover/groundtruth.tum").write_text(
        "".join(tum_row(stamp(k)[2], p) + "\n" for k, p in enumerate(sim["truth"]))
    )
    tables = {
        "relative_pose3": "rover/relative_pose3.csv",
        "range": "rover/range.csv",
        "groundtruth": "rover/groundtruth.tum",
    }
    robots = [{**ROBOTS[0], "tables": tables}, *ROBOTS[1:]]
    write_manifest({"name": "uwb", "robots": robots}, root)
    return root


TOPICS = {
    "name": "uwb",
    "robots": ROBOTS,
    "topics": {
        "/rover/odom": {"robot": "rover", "table": "relative_pose3", "sensor": "odom"},
        "/rover/truth": {"robot": "rover", "table": "groundtruth"},
        **{
            f"/rover/uwb/{b}": {"robot": "rover", "table": "range", "sensor": "uwb", "target": b}
            for b in BEACONS
        },
    },
}


def _msg(ts, msgtype, **kw):
    return ts.types[msgtype](**kw)


def _header(ts, k, ros1, frame="map"):
    sec, ns, _ = stamp(k)
    time = _msg(ts, "builtin_interfaces/msg/Time", sec=sec, nanosec=ns)
    extra = {"seq": k} if ros1 else {}
    return _msg(ts, "std_msgs/msg/Header", stamp=time, frame_id=frame, **extra)


def _pose_msg(ts, pose: gtsam.Pose3):
    q = pose.rotation().toQuaternion()
    t = pose.translation()
    return _msg(
        ts,
        "geometry_msgs/msg/Pose",
        position=_msg(ts, "geometry_msgs/msg/Point", x=t[0], y=t[1], z=t[2]),
        orientation=_msg(ts, "geometry_msgs/msg/Quaternion", x=q.x(), y=q.y(), z=q.z(), w=q.w()),
    )


def _range_msg(ts, k, ros1, r, lo=0.1, hi=50.0):
    return _msg(
        ts,
        "sensor_msgs/msg/Range",
        header=_header(ts, k, ros1, "uwb"),
        radiation_type=2,
        field_of_view=0.0,
        min_range=lo,
        max_range=hi,
        range=r,
    )


def bag_messages(sim: dict, ts, ros1: bool, bad: bool = False):
    """(topic, msgtype, receive time [ns], message or raw bytes) of the run; receive times
    jitter by up to 0.8 s, so bag order differs from header-stamp order."""
    rng = np.random.default_rng(1)
    cov = np.zeros((6, 6))
    cov[np.diag_indices(6)] = (SIGMAS**2)[[3, 4, 5, 0, 1, 2]]  # ROS order x y z rx ry rz
    zero_twist = _msg(
        ts,
        "geometry_msgs/msg/TwistWithCovariance",
        twist=_msg(
            ts,
            "geometry_msgs/msg/Twist",
            linear=_msg(ts, "geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0),
            angular=_msg(ts, "geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0),
        ),
        covariance=np.zeros(36),
    )
    out = []

    def add(topic, msgtype, k, msg):
        out.append((topic, msgtype, int((stamp(k)[2] + rng.uniform(0, 0.8)) * 1e9), msg))

    for k in range(N):
        pose = _msg(
            ts,
            "geometry_msgs/msg/PoseWithCovariance",
            pose=_pose_msg(ts, sim["odo"][k]),
            covariance=cov.ravel().copy(),
        )
        add(
            "/rover/odom",
            "nav_msgs/msg/Odometry",
            k,
            _msg(
                ts,
                "nav_msgs/msg/Odometry",
                header=_header(ts, k, ros1, "odom"),
                child_frame_id="base_link",
                pose=pose,
                twist=zero_twist,
            ),
        )
        add(
            "/rover/truth",
            "geometry_msgs/msg/PoseStamped",
            k,
            _msg(
                ts,
                "geometry_msgs/msg/PoseStamped",
                header=_header(ts, k, ros1),
                pose=_pose_msg(ts, sim["truth"][k]),
            ),
        )
        for b in BEACONS:
            add(
                f"/rover/uwb/{b}",
                "sensor_msgs/msg/Range",
                k,
                _range_msg(ts, k, ros1, sim["ranges"][b][k]),
            )
    if bad:  # each one a counted skip
        add("/rover/uwb/b1", "sensor_msgs/msg/Range", 3, _range_msg(ts, 3, ros1, float("nan")))
        add("/rover/uwb/b2", "sensor_msgs/msg/Range", 4, _range_msg(ts, 4, ros1, 80.0))
        add("/rover/bearing", "sensor_msgs/msg/Range", 5, _range_msg(ts, 5, ros1, 2.0))
        zero = _msg(ts, "geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0)
        add(
            "/rover/look",
            "geometry_msgs/msg/Vector3Stamped",
            6,
            _msg(ts, "geometry_msgs/msg/Vector3Stamped", header=_header(ts, 6, ros1), vector=zero),
        )
        add("/rover/look", "geometry_msgs/msg/Vector3Stamped", 7, b"\x00\x01\x00")
        add("/chatter", "std_msgs/msg/String", 8, _msg(ts, "std_msgs/msg/String", data="hi"))
    return out


def write_bag(sim: dict, path: Path, kind: str, bad: bool = False) -> Path:
    """`kind`: ros1 (.bag), sqlite3 or mcap (ROS 2 directories)."""
    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    msgs = bag_messages(sim, ts, ros1, bad)
    if ros1:
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=9, storage_plugin=plugin)
    with writer:
        conns = {}
        for topic, msgtype, _, _ in msgs:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
        for topic, msgtype, t, msg in sorted(msgs, key=lambda m: m[2]):
            if not isinstance(msg, bytes):
                msg = ts.serialize_ros1(msg, msgtype) if ros1 else ts.serialize_cdr(msg, msgtype)
            writer.write(conns[topic], t, msg)
    return path
