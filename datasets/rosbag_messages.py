"""Decoded bag messages -> rows of graphloc's tables (docs/rosbag.md, "Messages -> rows"). A bad
value raises `Bad(reason, text)`, which the importer counts as a skip naming bag, topic and
message index."""

from __future__ import annotations

import math

import cv2
import gtsam
import numpy as np

from graphloc.datasets.rosbag_topics import (
    CLOUD,
    COMPRESSED,
    IMAGE,
    MESSAGE_TYPES,
    ODOMETRY,
    POSE,
    TRANSFORM,
    VECTOR3,
    TopicMap,
)
from graphloc.textio import SkipReport
from graphloc.vision.markers import MarkerDetectorConfig, detect_markers

# ROS pose covariance order (x, y, z, rot x, rot y, rot z) -> GTSAM Pose3 tangent (rx..tz)
_ROS_TO_GTSAM = (3, 4, 5, 0, 1, 2)
# sensor_msgs/Image encodings the marker detector takes: channels, dtype, to BGR / grey
_ENCODINGS = {
    "mono8": (1, np.uint8),
    "8UC1": (1, np.uint8),
    "mono16": (1, np.dtype("<u2")),
    "16UC1": (1, np.dtype("<u2")),
    "bgr8": (3, np.uint8),
    "rgb8": (3, np.uint8),
    "bgra8": (4, np.uint8),
    "rgba8": (4, np.uint8),
}


class Bad(Exception):
    """A message's bad value: `reason` is the skip count's key."""

    def __init__(self, reason: str, text: str):
        super().__init__(text)
        self.reason = reason


def stamp(msg) -> float:
    st = msg.header.stamp
    t = st.sec + st.nanosec * 1e-9
    if not math.isfinite(t) or t < 0:  # 0 is a time: simulators' clocks start there
        raise Bad("bad_stamp", f"header stamp {st.sec}.{st.nanosec:09d} is not a time")
    return t


def _finite(*values) -> None:
    if not all(math.isfinite(v) for v in values):
        raise Bad("not_finite", "a field is NaN or inf")


def _unit(q) -> tuple:
    n = math.sqrt(sum(a * a for a in q))
    if not 0.5 < n < 2.0:
        raise Bad("bad_quaternion", f"orientation |q| = {n:.3g} is not a unit quaternion")
    return tuple(a / n for a in q)


def pose(msgtype: str, msg):
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
    return np.array(t), _unit(q), cov


def pose3(t, q) -> gtsam.Pose3:
    return gtsam.Pose3(gtsam.Rot3.Quaternion(q[3], q[0], q[1], q[2]), gtsam.Point3(*t))


def _direction(msgtype: str, msg) -> np.ndarray:
    v = msg.vector if msgtype == VECTOR3 else msg.point
    d = np.array([v.x, v.y, v.z], dtype=float)
    _finite(*d)
    n = float(np.linalg.norm(d))
    if n < 1e-12:
        raise Bad("bad_direction", "zero vector has no direction")
    return d / n


def _target(m: TopicMap, msg) -> str:
    if m.target is not None:
        return m.target
    frame = msg.header.frame_id
    if frame not in m.targets:
        raise Bad("unknown_frame", f"header.frame_id {frame!r} is not in field 'targets'")
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


def image_array(msgtype: str, msg) -> np.ndarray:
    """(H,W) uint8 grey or (H,W,3) uint8 BGR of a sensor_msgs/Image or CompressedImage."""
    if msgtype == COMPRESSED:
        img = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise Bad("bad_image", f"CompressedImage ({msg.format!r}) does not decode")
        return img if img.ndim == 2 else img[..., :3]
    if msg.encoding not in _ENCODINGS:
        raise Bad(
            "bad_image",
            f"encoding {msg.encoding!r} not supported (takes {', '.join(_ENCODINGS)})",
        )
    ch, dtype = _ENCODINGS[msg.encoding]
    dtype = np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if h <= 0 or w <= 0 or step < w * ch * dtype.itemsize or len(data) < h * step:
        raise Bad("bad_image", f"{w}x{h} image, step {step}: {len(data)} bytes of data")
    rows = data[: h * step].reshape(h, step)[:, : w * ch * dtype.itemsize]
    img = np.ascontiguousarray(rows).view(dtype).reshape(h, w, ch)
    if dtype.itemsize == 2:
        img = (img >> 8).astype(np.uint8)
    if ch == 1:
        return img[..., 0]
    img = img[..., :3]
    return np.ascontiguousarray(img[..., ::-1] if msg.encoding.startswith("rgb") else img)


def camera_params(msg) -> dict:
    """Pinhole intrinsics of a sensor_msgs/CameraInfo (ROS 2 `k`, `d`; ROS 1 `K`, `D`) as
    sensor params (docs/log_format.md: fx, fy, cx, cy, width, height, dist)."""
    K = np.asarray(getattr(msg, "k", None) if hasattr(msg, "k") else msg.K, dtype=float)
    D = np.asarray(getattr(msg, "d", None) if hasattr(msg, "d") else msg.D, dtype=float)
    if K.shape != (9,) or not np.isfinite(K).all() or K[0] <= 0 or K[4] <= 0:
        raise Bad("bad_camera_info", f"K = {K.tolist()} is not a pinhole matrix")
    if msg.distortion_model not in ("plumb_bob", "rational_polynomial", "") and D.any():
        raise Bad(
            "bad_camera_info",
            f"distortion model {msg.distortion_model!r} (takes plumb_bob, rational_polynomial)",
        )
    params = {
        "fx": float(K[0]),
        "fy": float(K[4]),
        "cx": float(K[2]),
        "cy": float(K[5]),
        "width": int(msg.width),
        "height": int(msg.height),
    }
    if D.size and D.any():
        params["dist"] = [float(v) for v in D]
    return params


def cloud_points(msg) -> tuple[np.ndarray, int]:
    """(N,3) finite points of a PointCloud2 (KISS-ICP's reader: fields x, y, z) and the number
    of non-finite points dropped."""
    from kiss_icp.tools.point_cloud2 import read_point_cloud

    names = {f.name for f in msg.fields}
    if not {"x", "y", "z"} <= names:
        raise Bad("bad_cloud", f"PointCloud2 has no x, y, z fields (fields: {sorted(names)})")
    total = int(msg.width) * int(msg.height)
    pts, _ = read_point_cloud(msg)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if not len(pts):
        raise Bad("bad_cloud", f"PointCloud2 holds no finite point (of {total})")
    return pts, total - len(pts)


def tf_extrinsics(edges: dict, body: str, frame: str) -> np.ndarray:
    """body_T_frame (4x4) through the tf tree `edges` (child -> (parent, parent_T_child 4x4));
    KeyError naming the frames when no chain of transforms connects them."""

    def up(f):  # ancestor -> ancestor_T_f, for f and each frame above it
        out, T = {f: np.eye(4)}, np.eye(4)
        while f in edges:
            f, parent_T = edges[f]
            T = parent_T @ T
            if f in out:  # a loop in the tree
                break
            out[f] = T
        return out

    a, b = up(body), up(frame)
    common = [f for f in a if f in b]
    if not common:
        raise KeyError(f"no tf / tf_static chain connects {body!r} and {frame!r}")
    c = common[0]
    return np.linalg.inv(a[c]) @ b[c]


def tf_edges(messages) -> dict:
    """child -> (parent, parent_T_child 4x4) of (TFMessage) messages; the first transform of
    each child holds (extrinsics are fixed)."""
    edges = {}
    for msg in messages:
        for tr in msg.transforms:
            child = tr.child_frame_id.lstrip("/")
            if child in edges:
                continue
            t, q = tr.transform.translation, tr.transform.rotation
            _finite(t.x, t.y, t.z, q.x, q.y, q.z, q.w)
            edges[child] = (
                tr.header.frame_id.lstrip("/"),
                pose3((t.x, t.y, t.z), _unit((q.x, q.y, q.z, q.w))).matrix(),
            )
    return edges


def _stamped(where: str, m: TopicMap, msgtype: str, msg, skips: SkipReport) -> float | None:
    """The message's header stamp if its type fits the table, else a counted skip (None)."""
    if msgtype not in MESSAGE_TYPES[m.table]:
        skips.add(
            "wrong_type",
            f"{where}: {msgtype} cannot fill table '{m.table}' "
            f"(takes {', '.join(MESSAGE_TYPES[m.table])})",
        )
        return None
    try:
        return stamp(msg)
    except (Bad, AttributeError) as exc:
        skips.add(getattr(exc, "reason", "malformed"), f"{where}: {exc}")
        return None


def message_rows(where0: str, m: TopicMap, i: int, msgtype: str, msg, skips: SkipReport) -> list:
    """Rows of message `i` of a topic whose rows stand alone (every table but relative_pose3),
    so a bag is converted as it streams (images and clouds are not kept); scans rows carry the
    (N,3) points in place of a path. The importer sorts the rows by (stamp, bag index)."""
    t = _stamped(f"{where0} message {i}", m, msgtype, msg, skips)
    if t is None:
        return []
    where = f"{where0} message {i} (stamp {t:.9f})"
    try:
        if m.table == "groundtruth":
            xyz, q, _ = pose(msgtype, msg)
            return [(t, *xyz, *q)]
        if m.table == "odometry":  # unicycle velocities: forward speed, yaw rate (body frame)
            tw = msg.twist.twist if msgtype == ODOMETRY else msg.twist
            v, omega = float(tw.linear.x), float(tw.angular.z)
            _finite(v, omega)
            return [(t, m.sensor, v, omega)]
        if m.table == "range":
            r = float(msg.range)
            _finite(r)
            lo, hi = float(msg.min_range), float(msg.max_range)
            if r <= 0 or r < lo or (hi > lo and r > hi):
                raise Bad("out_of_range", f"range {r:g} m outside [{lo:g}, {hi:g}] (or not > 0)")
            return [(t, m.sensor, _target(m, msg), r)]
        if m.table == "bearing":
            return [(t, m.sensor, _target(m, msg), *_direction(msgtype, msg))]
        if msgtype == CLOUD:
            pts, dropped = cloud_points(msg)
            if dropped:
                skips.add("nonfinite_points", f"{where}: {dropped} NaN / inf points", dropped)
            return [(t, m.sensor, pts)]
        if msgtype in (IMAGE, COMPRESSED):
            config = MarkerDetectorConfig(**{**m.detector, "expected": 4})
            det = detect_markers(image_array(msgtype, msg), config)
            if det.status != "ok":
                raise Bad("marker_shortfall", f"{det.shortfall} of 4 markers not found")
            return [(t, m.sensor, m.target, k, *det.points[k]) for k in range(4)]
        dets, bad = _detections(m, msg)  # Detection2DArray
        for text in bad:
            skips.add("bad_detection", f"{where}: {text}")
        return [(t, m.sensor, tgt, k, u, v) for tgt, k, u, v in dets]
    except Bad as exc:
        skips.add(exc.reason, f"{where}: {exc}")
    except (AttributeError, TypeError, ValueError) as exc:
        skips.add("malformed", f"{where}: {exc}")
    return []


def count_backwards(where0: str, stamps: list, notes: SkipReport) -> None:
    """Count in `notes` (reason `stamp_backwards`) every message of one topic stamped before an
    earlier message (`stamps`: (stamp, bag index) in bag order), which the import re-sorts."""
    latest, seen = -math.inf, set()
    for t, i in stamps:
        if i in seen:  # several rows of one message (detections)
            continue
        seen.add(i)
        if t < latest:
            notes.add(
                "stamp_backwards",
                f"{where0} message {i}: stamp {t:.9f} is before an earlier message's "
                f"{latest:.9f} (re-sorted by stamp)",
            )
        latest = max(latest, t)


def pose_rows(where0: str, m: TopicMap, msgs: list, skips: SkipReport, notes: SkipReport) -> list:
    """relative_pose3 rows of one topic's messages [(bag index, msgtype, msg)]: increments
    between consecutive poses in header-stamp order (stable: bag order breaks ties; a message
    stamped before an earlier one counted in `notes`, `count_backwards`)."""
    stamped = []
    for i, msgtype, msg in msgs:
        t = _stamped(f"{where0} message {i}", m, msgtype, msg, skips)
        if t is not None:
            stamped.append((t, i, msgtype, msg))
    count_backwards(where0, [s[:2] for s in stamped], notes)
    stamped.sort(key=lambda s: (s[0], s[1]))
    chain = PoseChain(where0, m, skips)
    out = [chain.add(i, msgtype, msg, t) for t, i, msgtype, msg in stamped]
    return [row for row in out if row is not None]


class PoseChain:
    """One pose topic's relative_pose3 rows, message by message in stamp order (a sorted bag
    topic, or a live topic as it arrives), each against the previous good one (`_increment`);
    a bad message, or live one stamped before the previous, is a counted skip."""

    def __init__(self, where0: str, m: TopicMap, skips: SkipReport):
        self.where0, self.m, self.skips = where0, m, skips
        self.prev = None  # (t, xyz, q, cov) of the previous good message

    def add(self, i: int, msgtype: str, msg, t: float | None = None):
        """The row from the previous message's pose to message `i`'s (None: the first, or a
        skip); `t`: its header stamp when already read (`_stamped`)."""
        if t is None:
            t = _stamped(f"{self.where0} message {i}", self.m, msgtype, msg, self.skips)
            if t is None:
                return None
        where = f"{self.where0} message {i} (stamp {t:.9f})"
        try:
            if self.prev is not None and t < self.prev[0]:
                raise Bad(
                    "stamp_backwards",
                    f"stamp before the previous message's {self.prev[0]:.9f} (not re-sorted live)",
                )
            xyz, q, cov = pose(msgtype, msg)
            row = (
                None
                if self.prev is None
                else _increment(self.m, self.prev, (t, xyz, q, cov), msgtype)
            )
            self.prev = (t, xyz, q, cov)
            return row
        except Bad as exc:
            self.skips.add(exc.reason, f"{where}: {exc}")
        except (AttributeError, TypeError, ValueError) as exc:
            self.skips.add("malformed", f"{where}: {exc}")
        return None


def _increment(m: TopicMap, prev, cur, msgtype: str):
    """relative_pose3 row from the pose at `prev` to the pose at `cur`, in the frame at prev;
    sigmas: the topic's fixed `sigmas`, else the current message's covariance diagonal
    ("step": the covariance of the step since the previous message) or the growth of the
    diagonal ("difference": an accumulating dead-reckoning covariance)."""
    t0, xyz0, q0, cov0 = prev
    t, xyz, q, cov = cur
    if not t > t0:
        raise Bad("duplicate_stamp", f"stamp equals the previous message's ({t0:.9f})")
    if m.sigmas is not None:
        sig = np.array(m.sigmas)
    else:
        if cov is None:
            raise Bad("no_covariance", f"{msgtype} carries no covariance: give field 'sigmas'")
        var = np.diag(cov) - (np.diag(cov0) if m.covariance == "difference" else 0.0)
        sig = np.sqrt(np.clip(var, 0.0, None))[list(_ROS_TO_GTSAM)]
        if not (np.isfinite(sig).all() and (sig > 0).all()):
            raise Bad(
                "no_covariance",
                f"covariance diagonal gives sigmas {sig.tolist()} "
                f"({m.covariance}); give field 'sigmas'",
            )
    rel = pose3(xyz0, q0).between(pose3(xyz, q))
    qw, qx, qy, qz = rel.rotation().toQuaternion().coeffs()[[3, 0, 1, 2]]
    return (t, m.sensor, t0, *rel.translation(), qx, qy, qz, qw, *sig)
