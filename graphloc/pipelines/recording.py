"""Results out for viewers: a run's estimates, candidate sets and point clouds (`Recording`) as an
MCAP file of ROS 2 messages (`write_mcap`) or a Rerun recording (`write_rerun`); topics and
entities in docs/rosbag.md."""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.manifest import MANIFEST
from graphloc.mapping.io import read_labelled_cloud, read_scan, read_tum
from graphloc.pipelines.groundtruth import groundtruth_rows
from graphloc.pipelines.team_graph import TeamResult
from graphloc.run import TeamRun

FRAME = "map"
ROBOT_RGB = np.array([[217, 38, 25], [25, 76, 230], [25, 178, 51], [153, 51, 178], [230, 140, 0]])


@dataclass(frozen=True)
class Track:
    """One trajectory: (N,) times [s] and (N,7) x y z qx qy qz qw rows (finite rows only)."""

    robot: str
    label: str  # "batch" / "online" (the estimate), "dead_reckoning", "groundtruth"
    times: np.ndarray
    rows: np.ndarray


@dataclass(frozen=True)
class CandidateFrame:
    """One candidate set as decided: where each candidate puts the observer's body (K,3) and how
    it turns it (K,4 x y z w; None where the solve states none), each candidate's posterior
    weight (K,; NaN where the solve states none), the committed candidate (-1: none), its
    posterior (else the largest) and the committed pose."""

    time: float
    robot: str
    target: str
    xyz: np.ndarray
    weights: np.ndarray
    committed: int
    probability: float
    pose: np.ndarray
    quat: np.ndarray | None = None


@dataclass(frozen=True)
class Cloud:
    """(N,3) points in the world frame with an (N,) integer robot label per point."""

    name: str
    points: np.ndarray
    robot: np.ndarray
    time: float | None = None


@dataclass
class Recording:
    name: str
    tracks: list = field(default_factory=list)
    candidates: list = field(default_factory=list)
    clouds: list = field(default_factory=list)

    def end_time(self) -> float:
        times = [t.times[-1] for t in self.tracks if len(t.times)]
        times += [c.time for c in self.candidates]
        return float(max(times, default=0.0))


def _finite_track(robot: str, label: str, times, rows) -> Track | None:
    rows = np.asarray(rows, dtype=float).reshape(-1, 7)
    ok = np.isfinite(rows).all(axis=1)
    if not ok.any():
        return None
    return Track(robot, label, np.asarray(times, dtype=float)[ok], rows[ok])


def team_recording(result: TeamResult, run: TeamRun, source=None) -> Recording:
    """The recording of a `graphloc smooth` / `online` result (`team_graph.solve`); with the
    run's log directory `source`, its robots' scans too (`scan_clouds`)."""
    rec = Recording(run.name)
    if source is not None and (Path(source) / MANIFEST).is_file():
        rec.clouds += scan_clouds(source, result, run)
    for r, robot in enumerate(run.robots):
        times = result.node_times[r]
        for label, rows in (
            (result.mode, result.estimate[r]),
            ("dead_reckoning", result.dead_reckoning[r]),
        ):
            track = _finite_track(robot.name, label, times, rows)
            if track is not None:
                rec.tracks.append(track)
        ref = groundtruth_rows(run, r)
        if ref is not None:
            track = _finite_track(robot.name, "groundtruth", *ref)
            if track is not None:
                rec.tracks.append(track)
    for d in result.decisions:  # max-mixture sets chosen at the estimate
        xyz = np.asarray(d.candidates_xyz, dtype=float).reshape(-1, 3)
        rec.candidates.append(
            CandidateFrame(
                float(d.time),
                run.robots[d.robot].name,
                run.robots[d.target].name,
                xyz,
                candidate_weights(d, len(xyz)),
                int(d.committed),
                float(d.probability),
                np.asarray(d.pose, dtype=float),
                None if d.candidates_quat is None else np.asarray(d.candidates_quat, float),
            )
        )
    return rec


def candidate_weights(decision, k: int) -> np.ndarray:
    """(k,) posterior weight of every candidate of a decision (`SetOutcome.probabilities`: the
    tracker's posterior, or the max-mixture's component weights at the estimate); a decision
    without them (a max-mixture the solve never reached) has only the committed one's."""
    if decision.probabilities is not None:
        w = np.asarray(decision.probabilities, dtype=float).reshape(-1)
        if len(w) != k:
            raise ValueError(f"decision at t={decision.time}: {len(w)} weights for {k} candidates")
        return w
    w = np.full(k, np.nan)
    if 0 <= decision.committed < k:
        w[decision.committed] = decision.probability
    return w


def scan_clouds(root, result: TeamResult, run: TeamRun, voxel: float = 0.05) -> list:
    """Each robot's scans placed by the estimate of the pose nearest in time (through the
    scanner's extrinsics), voxel-downsampled; a scan without a pose within `voxel` s is left out."""
    import open3d as o3d

    clouds = []
    for r, robot in enumerate(run.robots):
        scans = [s for s in run.scans if s.robot == r]
        times, est = np.asarray(result.node_times[r], dtype=float), result.estimate[r]
        if not scans or not len(times):
            continue
        parts = []
        for scan in scans:
            k = int(np.argmin(np.abs(times - scan.time)))
            if abs(times[k] - scan.time) > voxel or not np.isfinite(est[k]).all():
                continue
            T = np.eye(4)
            T[:3, :3] = Rotation.from_quat(est[k, 3:7]).as_matrix()
            T[:3, 3] = est[k, :3]
            T = T @ scan.body_T_sensor.matrix()
            pts = read_scan(scan.path, warn=False)[0]
            parts.append(pts @ T[:3, :3].T + T[:3, 3])
        if parts:
            cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(np.vstack(parts)))
            pts = cloud.voxel_down_sample(voxel).point.positions.numpy().astype(float)
            clouds.append(Cloud(f"scans_{robot.name}", pts, np.full(len(pts), r), times[-1]))
    return clouds


def fusion_recording(out_dir) -> Recording:
    """The recording of a `graphloc fuse-maps` output directory: the fused map
    (`fused_map.ply`, points labelled by robot) and the robots' `trajectory_*.tum`."""
    out_dir = Path(out_dir)
    rec = Recording(out_dir.name)
    for path in sorted(out_dir.glob("trajectory_*.tum")):
        times, poses = read_tum(path)
        rows = np.column_stack([poses[:, :3, 3], Rotation.from_matrix(poses[:, :3, :3]).as_quat()])
        rec.tracks.append(Track(path.stem[len("trajectory_") :], "fused", times, rows))
    points, robot = read_labelled_cloud(out_dir / "fused_map.ply")
    rec.clouds.append(Cloud("fused_map", points, robot, rec.end_time()))
    return rec


# ---- MCAP (rosbags' ROS 2 writer) ------------------------------------------------------------
def _time(ts, t: float):
    sec = int(np.floor(t))
    ns = min(int(round((t - sec) * 1e9)), 999_999_999)
    return ts.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=ns)


def _pose_stamped(ts, t: float, row) -> object:
    T = ts.types
    header = T["std_msgs/msg/Header"](stamp=_time(ts, t), frame_id=FRAME)
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=row[0], y=row[1], z=row[2]),
        orientation=T["geometry_msgs/msg/Quaternion"](x=row[3], y=row[4], z=row[5], w=row[6]),
    )
    return T["geometry_msgs/msg/PoseStamped"](header=header, pose=pose)


def _cloud(ts, t: float, columns: dict):
    """PointCloud2 of float32 fields (name -> (N,) values), unordered (height 1)."""
    T = ts.types
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype="<f4") for n in names])
    fields = [
        T["sensor_msgs/msg/PointField"](name=n, offset=4 * i, datatype=7, count=1)
        for i, n in enumerate(names)
    ]
    return T["sensor_msgs/msg/PointCloud2"](
        header=T["std_msgs/msg/Header"](stamp=_time(ts, t), frame_id=FRAME),
        height=1,
        width=len(data),
        fields=fields,
        is_bigendian=False,
        point_step=4 * len(names),
        row_step=4 * len(names) * len(data),
        data=np.frombuffer(np.ascontiguousarray(data).tobytes(), dtype=np.uint8),
        is_dense=True,
    )


def mcap_messages(rec: Recording, ts) -> list:
    """(topic, msgtype, time [s], message) of the recording, in time order per topic."""
    out = []
    pose, path, cloud = (
        "geometry_msgs/msg/PoseStamped",
        "nav_msgs/msg/Path",
        "sensor_msgs/msg/PointCloud2",
    )
    for tr in rec.tracks:
        base = f"/graphloc/{tr.robot}"
        poses = [_pose_stamped(ts, t, r) for t, r in zip(tr.times, tr.rows)]
        estimate = tr.label not in ("dead_reckoning", "groundtruth")
        if estimate:
            out += [(f"{base}/pose", pose, t, p) for t, p in zip(tr.times, poses)]
        topic = f"{base}/{'path' if estimate else tr.label}"
        header = ts.types["std_msgs/msg/Header"](stamp=_time(ts, tr.times[-1]), frame_id=FRAME)
        msg = ts.types[path](header=header, poses=poses)
        out.append((topic, path, float(tr.times[-1]), msg))
    for c in rec.candidates:
        base = f"/graphloc/{c.robot}"
        chosen = (np.arange(len(c.xyz)) == c.committed).astype(float)
        columns = {"x": c.xyz[:, 0], "y": c.xyz[:, 1], "z": c.xyz[:, 2], "committed": chosen}
        columns["weight"] = c.weights
        out.append((f"{base}/candidates", cloud, c.time, _cloud(ts, c.time, columns)))
        if c.quat is not None:  # every candidate's pose, in the cloud's order
            header = ts.types["std_msgs/msg/Header"](stamp=_time(ts, c.time), frame_id=FRAME)
            poses = [_pose_stamped(ts, c.time, np.r_[p, q]).pose for p, q in zip(c.xyz, c.quat)]
            msg = ts.types["geometry_msgs/msg/PoseArray"](header=header, poses=poses)
            out.append((f"{base}/candidate_poses", "geometry_msgs/msg/PoseArray", c.time, msg))
        if c.committed >= 0:
            out.append((f"{base}/committed", pose, c.time, _pose_stamped(ts, c.time, c.pose)))
    for cl in rec.clouds:
        t = cl.time if cl.time is not None else rec.end_time()
        columns = {"x": cl.points[:, 0], "y": cl.points[:, 1], "z": cl.points[:, 2]}
        columns["robot"] = cl.robot
        out.append((f"/graphloc/map/{cl.name}", cloud, t, _cloud(ts, t, columns)))
    return out


def write_mcap(rec: Recording, path) -> dict:
    """Write the recording as one MCAP file; returns topic -> message count."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    if path.suffix != ".mcap":
        raise ValueError(f"--mcap {path}: the file name must end in .mcap")
    path.parent.mkdir(parents=True, exist_ok=True)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    msgs = sorted(mcap_messages(rec, ts), key=lambda m: m[2])
    counts: dict = {}
    with tempfile.TemporaryDirectory(prefix="graphloc-mcap-", dir=path.parent) as tmp:
        bag = Path(tmp) / path.stem
        with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conns = {}
            for topic, msgtype, t, msg in msgs:
                if topic not in conns:
                    conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
                stamp_ns = max(int(round(t * 1e9)), 0)
                writer.write(conns[topic], stamp_ns, ts.serialize_cdr(msg, msgtype))
                counts[topic] = counts.get(topic, 0) + 1
        shutil.move(str(next(bag.glob("*.mcap"))), path)
    return counts


# ---- Rerun ------------------------------------------------------------------------------------
def write_rerun(rec: Recording, path) -> list[str]:
    """Write the recording as a Rerun `.rrd` file; returns the entity paths written."""
    try:
        import rerun as rr
    except ImportError:
        raise ValueError(
            f"--rerun {path}: the Rerun SDK is not installed (pip install 'graphloc[viz]')"
        ) from None
    path = Path(path)
    if path.suffix != ".rrd":
        raise ValueError(f"--rerun {path}: the file name must end in .rrd")
    path.parent.mkdir(parents=True, exist_ok=True)
    stream = rr.RecordingStream("graphloc", recording_id=rec.name)
    stream.save(str(path))
    robots = sorted({t.robot for t in rec.tracks} | {c.robot for c in rec.candidates})
    colour = {name: ROBOT_RGB[i % len(ROBOT_RGB)] for i, name in enumerate(robots)}
    entities = []
    for tr in rec.tracks:
        grey = tr.label in ("groundtruth", "dead_reckoning")
        rgb = np.array([120, 120, 120]) if grey else colour[tr.robot]
        entity = f"world/{tr.robot}/{tr.label}"
        stream.send_columns(
            entity,
            indexes=[rr.TimeColumn("time", timestamp=tr.times)],
            columns=rr.Points3D.columns(positions=tr.rows[:, :3]),
        )
        stream.log(entity, rr.Points3D.from_fields(colors=rgb, radii=0.05), static=True)
        stream.log(f"{entity}/path", rr.LineStrips3D([tr.rows[:, :3]], colors=rgb), static=True)
        entities += [entity, f"{entity}/path"]
    for c in rec.candidates:
        stream.set_time("time", timestamp=c.time)
        chosen = np.arange(len(c.xyz)) == c.committed
        labels = [
            f"{c.target} #{k} p={w:.2f}" + (" committed" if k == c.committed else "")
            for k, w in enumerate(c.weights)
        ]
        rgb = np.where(chosen[:, None], [40, 200, 40], [220, 40, 40])
        radii = 0.03 + 0.12 * np.nan_to_num(c.weights)
        stream.log(
            f"world/{c.robot}/candidates",
            rr.Points3D(c.xyz, colors=rgb, labels=labels, radii=radii),
            rr.AnyValues(weight=c.weights, committed=chosen.astype(np.uint8)),
        )
        entities.append(f"world/{c.robot}/candidates")
        if c.quat is not None:  # each candidate's orientation: a flat box along its body axes
            stream.log(
                f"world/{c.robot}/candidates/poses",
                rr.Boxes3D(
                    centers=c.xyz,
                    half_sizes=np.tile([0.15, 0.1, 0.02], (len(c.xyz), 1)),
                    quaternions=[rr.Quaternion(xyzw=q) for q in c.quat],
                    colors=rgb,
                ),
            )
            entities.append(f"world/{c.robot}/candidates/poses")
        if c.committed >= 0:
            stream.log(
                f"world/{c.robot}/committed",
                rr.Transform3D(translation=c.pose[:3], quaternion=rr.Quaternion(xyzw=c.pose[3:])),
            )
            entities.append(f"world/{c.robot}/committed")
    for cl in rec.clouds:
        if cl.time is not None:
            stream.set_time("time", timestamp=cl.time)
        rgb = ROBOT_RGB[np.asarray(cl.robot, dtype=int) % len(ROBOT_RGB)]
        stream.log(f"world/map/{cl.name}", rr.Points3D(cl.points, colors=rgb, radii=0.01))
        entities.append(f"world/map/{cl.name}")
    stream.flush()
    stream.disconnect()
    return sorted(set(entities))


def write_recordings(rec: Recording, mcap=None, rerun=None) -> dict:
    """The verbs' `--mcap FILE` / `--rerun FILE`: what was written (file -> topics / entities)."""
    out = {}
    if mcap is not None:
        out[str(mcap)] = write_mcap(rec, mcap)
    if rerun is not None:
        out[str(rerun)] = write_rerun(rec, rerun)
    return out
