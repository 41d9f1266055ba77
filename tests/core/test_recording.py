"""Results out for viewers (issue 18; graphloc/pipelines/recording.py): `smooth --mcap FILE
--rerun FILE` on a simulated run with P3P candidate sets; the MCAP file is read back with the
`mcap` reader (topics, schemas, message counts against the TUM files and decisions.csv written
beside it), the `.rrd` with Rerun's own reader (every entity); a fuse-maps output directory's
fused map and trajectories through `fusion_recording`."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore

from graphloc.cli import main
from graphloc.eval import write_tum
from graphloc.mapping.io import write_labelled_cloud
from graphloc.pipelines.recording import fusion_recording, write_mcap, write_rerun


def mcap_counts(path: Path) -> tuple[dict, dict]:
    """topic -> message count and topic -> schema name, from the file's summary."""
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    counts = {
        summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()
    }
    schemas = {ch.topic: summary.schemas[ch.schema_id].name for ch in summary.channels.values()}
    return counts, schemas


def mcap_messages(path: Path, topic: str) -> list:
    """The topic's messages decoded (CDR) with rosbags' typestore."""
    ts = get_typestore(Stores.ROS2_HUMBLE)
    out = []
    with open(path, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages(topics=[topic]):
            out.append(ts.deserialize_cdr(message.data, schema.name))
    return out


def rrd_entities(path: Path) -> set:
    from rerun.chunk import RrdReader

    store = RrdReader(path).stream().collect()
    return {e.lstrip("/") for e in store.schema().entity_paths()}


@pytest.fixture(scope="module")
def smoothed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rec")
    assert main(["simulate", "feng-probabilistic", "--out", str(tmp / "run")]) == 0
    args = ["smooth", str(tmp / "run"), "--out", str(tmp / "out"), "--no-progress"]
    args += ["--mcap", str(tmp / "out/run.mcap"), "--rerun", str(tmp / "out/run.rrd")]
    assert main(args) == 0
    return tmp / "out"


def test_smooth_mcap_has_every_topic_and_count(smoothed):
    counts, schemas = mcap_counts(smoothed / "run.mcap")
    with open(smoothed / "decisions.csv") as fh:
        decisions = list(csv.DictReader(fh))
    assert decisions
    robots = sorted({p.name.rsplit("_", 1)[0] for p in smoothed.glob("*_batch.tum")})
    want = {}
    for robot in robots:
        poses = np.loadtxt(smoothed / f"{robot}_batch.tum", ndmin=2)
        want[f"/graphloc/{robot}/pose"] = len(poses)
        want[f"/graphloc/{robot}/path"] = 1
        want[f"/graphloc/{robot}/dead_reckoning"] = 1
        if (smoothed / f"{robot}_groundtruth.tum").exists():
            want[f"/graphloc/{robot}/groundtruth"] = 1
        mine = [d for d in decisions if d["robot"] == robot]
        if mine:
            want[f"/graphloc/{robot}/candidates"] = len(mine)
            want[f"/graphloc/{robot}/candidate_poses"] = len(mine)
            want[f"/graphloc/{robot}/committed"] = sum(int(d["committed"]) >= 0 for d in mine)
    assert counts == want
    assert schemas["/graphloc/climber/path"] == "nav_msgs/msg/Path"
    assert schemas["/graphloc/climber/candidates"] == "sensor_msgs/msg/PointCloud2"
    # the path holds the estimate written to TUM; each candidate cloud the set's candidates
    (path,) = mcap_messages(smoothed / "run.mcap", "/graphloc/climber/path")
    tum = np.loadtxt(smoothed / "climber_batch.tum", ndmin=2)
    xyz = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z] for p in path.poses])
    assert np.abs(xyz - tum[:, 1:4]).max() < 1e-9
    clouds = mcap_messages(smoothed / "run.mcap", "/graphloc/climber/candidates")
    first = next(d for d in decisions if d["robot"] == "climber")
    assert clouds[0].width == int(first["candidates"])
    fields = np.frombuffer(clouds[0].data.tobytes(), "<f4").reshape(clouds[0].width, 5)
    assert fields[:, 3].sum() == (int(first["committed"]) >= 0)
    # the set's probability in decisions.csv: the committed candidate's weight, else the largest
    j = int(first["committed"]) if int(first["committed"]) >= 0 else int(np.argmax(fields[:, 4]))
    assert abs(fields[j, 4] - float(first["probability"])) < 1e-5


def test_smooth_rerun_recording_holds_every_entity(smoothed):
    entities = rrd_entities(smoothed / "run.rrd")
    for label in ("batch", "dead_reckoning", "groundtruth"):
        assert f"world/climber/{label}" in entities and f"world/climber/{label}/path" in entities
    assert {"world/climber/candidates", "world/climber/committed", "world/ground/batch"} <= entities
    assert "world/climber/candidates/poses" in entities


def rrd_columns(path: Path, entity: str) -> list:
    """The rows logged to `entity` (Rerun's chunks as Arrow record batches), in time order."""
    from rerun.chunk import RrdReader

    rows = []
    for chunk in RrdReader(path).stream():
        if chunk.entity_path.lstrip("/") == entity:
            batch = chunk.to_record_batch().to_pydict()
            rows += [dict(zip(batch, values)) for values in zip(*batch.values())]
    return sorted(rows, key=lambda r: r["time"])


@pytest.mark.parametrize(
    "scenario, overrides, route",
    [
        ("feng-probabilistic", [], "tracker"),
        ("crawler-pair", ["--width", "320", "--height", "240"], "mixture"),
    ],
)
def test_every_candidate_carries_its_weight(tmp_path, scenario, overrides, route):
    """Both candidate routes of the solve: every candidate of every set, read back from the
    MCAP cloud and the .rrd components, carries the solve's posterior weight
    (`Decision.probabilities`: the HypothesisTracker's posterior, or the max-mixture's
    component weights chosen at the estimate) and the committed one is marked."""
    from graphloc.datasets import open_run
    from graphloc.pipelines.recording import team_recording
    from graphloc.pipelines.team_graph import solve
    from graphloc.runner.team_run import team_graph
    from graphloc.pipelines.team_graph.options import RunOptions

    assert main(["simulate", scenario, "--out", str(tmp_path / "run")] + overrides) == 0
    run = open_run(tmp_path / "run")
    result = solve(team_graph(run, RunOptions().graph_config()), mode="batch")
    rec = team_recording(result, run)
    write_mcap(rec, tmp_path / "r.mcap")
    write_rerun(rec, tmp_path / "r.rrd")
    decided = {}
    for d in result.decisions:
        assert (d.mixture is not None) == (route == "mixture")
        decided.setdefault(run.robots[d.robot].name, []).append(d)
    assert decided
    for robot, ds in decided.items():
        ds = sorted(ds, key=lambda d: d.time)  # stable: the order they were written in
        clouds = mcap_messages(tmp_path / "r.mcap", f"/graphloc/{robot}/candidates")
        logged = rrd_columns(tmp_path / "r.rrd", f"world/{robot}/candidates")
        poses = mcap_messages(tmp_path / "r.mcap", f"/graphloc/{robot}/candidate_poses")
        assert len(poses) == len(ds)
        assert len(clouds) == len(logged) == len(ds)
        for d, cloud, row, pa in zip(ds, clouds, logged, poses):
            k = len(d.candidates_xyz)
            assert [f.name for f in cloud.fields] == ["x", "y", "z", "committed", "weight"]
            data = np.frombuffer(cloud.data.tobytes(), "<f4").reshape(cloud.width, 5)
            want = np.asarray(d.probabilities, dtype=float)
            # the tracker keeps some mass off the candidates (none of them right)
            assert len(want) == k and (want >= 0).all() and want.sum() <= 1.0 + 1e-9
            np.testing.assert_allclose(data[:, 4], want, rtol=1e-6, atol=1e-7)
            np.testing.assert_allclose(np.asarray(row["weight"]), want, rtol=0, atol=1e-12)
            marked = (np.arange(k) == d.committed).astype(int)
            assert (data[:, 3] == marked).all() and list(row["committed"]) == list(marked)
            assert len(row["Points3D:labels"]) == k
            if d.committed >= 0:
                assert f"p={want[d.committed]:.2f} committed" in row["Points3D:labels"][d.committed]
            # every candidate's pose: the cloud's position and the decision's orientation
            assert abs(_stamp(pa) - d.time) < 1e-6
            got = np.array(
                [
                    [p.position.x, p.position.y, p.position.z]
                    + [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]
                    for p in pa.poses
                ]
            )
            np.testing.assert_allclose(got[:, :3], d.candidates_xyz, atol=1e-9)
            np.testing.assert_allclose(got[:, 3:], d.candidates_quat, atol=1e-9)
            if route == "mixture":  # chosen at the estimate: the heaviest component
                assert d.committed == int(np.argmax(want)) and abs(want.sum() - 1.0) < 1e-9
    assert any(d.committed >= 0 for ds in decided.values() for d in ds)


def test_fused_map_recording(tmp_path):
    rng = np.random.default_rng(0)
    points = rng.uniform(-3, 3, (500, 3))
    robot = (np.arange(500) >= 300).astype(int)
    write_labelled_cloud(tmp_path / "fused_map.ply", points, robot)
    times = np.arange(5) * 0.1
    poses = np.tile(np.eye(4), (5, 1, 1))
    poses[:, 0, 3] = times
    write_tum(tmp_path / "trajectory_ground.tum", times, poses)
    write_tum(tmp_path / "trajectory_ceiling.tum", times, poses)
    rec = fusion_recording(tmp_path)
    counts = write_mcap(rec, tmp_path / "map.mcap")
    assert counts == mcap_counts(tmp_path / "map.mcap")[0]
    assert counts["/graphloc/map/fused_map"] == 1 and counts["/graphloc/ground/pose"] == 5
    (cloud,) = mcap_messages(tmp_path / "map.mcap", "/graphloc/map/fused_map")
    data = np.frombuffer(cloud.data.tobytes(), "<f4").reshape(cloud.width, 4)
    assert np.abs(data[:, :3] - points).max() < 1e-5 and (data[:, 3] == robot).all()
    assert "world/map/fused_map" in write_rerun(rec, tmp_path / "m.rrd")
    assert "world/map/fused_map" in rrd_entities(tmp_path / "m.rrd")
    with pytest.raises(ValueError, match="must end in .mcap"):
        write_mcap(rec, tmp_path / "map.bag")


def test_scans_are_placed_by_the_estimate(tmp_path):
    """A rover's four scans of a box room (a scanner 0.3 m above the body, KISS-ICP odometry):
    the recording's scan cloud is the scans placed by the estimate written to TUM through the
    scanner's extrinsics (voxel centroids: most voxels hold one point)."""
    import open3d as o3d
    from scipy.spatial import cKDTree
    from scipy.spatial.transform import Rotation

    from graphloc.manifest import write_manifest
    from graphloc.log_writer import write_table

    rng = np.random.default_rng(1)
    room = np.vstack(  # walls at x, y = +-4, floor 0, ceiling 3
        [
            np.column_stack(
                [np.full(1000, s * 4.0), rng.uniform(-4, 4, 1000), rng.uniform(0, 3, 1000)]
            )
            for s in (-1, 1)
        ]
        + [
            np.column_stack(
                [rng.uniform(-4, 4, 1000), np.full(1000, s * 4.0), rng.uniform(0, 3, 1000)]
            )
            for s in (-1, 1)
        ]
        + [np.column_stack([rng.uniform(-4, 4, (1500, 2)), np.full(1500, z)]) for z in (0.0, 3.0)]
    )
    (tmp_path / "log/rover").mkdir(parents=True)
    rows = []
    for k in range(4):
        sensor_at = np.array([0.2 * k, 0.1 * k, 0.3])  # the body moves along (0.2, 0.1, 0)
        cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(room - sensor_at))
        o3d.t.io.write_point_cloud(str(tmp_path / f"log/rover/{k}.ply"), cloud)
        rows.append((0.5 * k, "lidar", f"rover/{k}.ply"))
    write_table(tmp_path / "log/rover/scans.csv", "scans", rows)
    robot = {
        "name": "rover",
        "kind": "ground",
        "planar": False,
        "initial_pose": [0, 0, 0, 0, 0, 0, 1],
        "sensors": [{"name": "lidar", "type": "scanner", "extrinsics": {"xyz": [0, 0, 0.3]}}],
        "tables": {"scans": "rover/scans.csv"},
    }
    write_manifest({"name": "box", "robots": [robot]}, tmp_path / "log")
    args = ["smooth", str(tmp_path / "log"), "--out", str(tmp_path / "out"), "--no-progress"]
    assert (
        main(args + ["--mcap", str(tmp_path / "box.mcap"), "--rerun", str(tmp_path / "b.rrd")]) == 0
    )
    (logged,) = rrd_columns(tmp_path / "b.rrd", "world/map/scans_rover")
    (cloud,) = mcap_messages(tmp_path / "box.mcap", "/graphloc/map/scans_rover")
    assert len(logged["Points3D:positions"]) == cloud.width
    pts = np.frombuffer(cloud.data.tobytes(), "<f4").reshape(cloud.width, 4)[:, :3]
    est = np.loadtxt(tmp_path / "out/rover_batch.tum", ndmin=2)
    assert len(est) == 4
    placed = []
    for k, row in enumerate(est):
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat(row[4:8]).as_matrix()
        T[:3, 3] = row[1:4]
        T = T @ np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.3], [0, 0, 0, 1]])
        scan = np.asarray(
            o3d.t.io.read_point_cloud(str(tmp_path / f"log/rover/{k}.ply")).point.positions.numpy(),
            float,
        )
        placed.append(scan @ T[:3, :3].T + T[:3, 3])
    d = cKDTree(np.vstack(placed)).query(pts)[0]
    assert len(pts) > 1000 and np.median(d) < 1e-4 and np.percentile(d, 95) < 0.09


def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
