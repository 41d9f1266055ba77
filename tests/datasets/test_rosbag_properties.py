"""Issue 17, ROS bags: a property-based test of the bag reader through the front door
(`graphloc.datasets.open_run`, the loader `smooth` / `online` / `validate` use). A valid run
(seed 004's `kaushik-p3p-error`: odometry, marker detections, ground truth, plus two scans) is
written as ROS 1, ROS 2 sqlite3 and MCAP bags by `benchmarks.rosbag_export`; hypothesis
truncates them, flips bytes, maps topics to other topics' messages and names a CameraInfo topic
the bag does not hold. Whatever it does, the reader returns a run whose skips each name the bag,
a topic and a message index, or raises a ValueError naming the bag -- never another exception;
uncorrupted bags give the exact skip counts their mapping implies."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
import yaml
from rosbags.highlevel import AnyReader
from hypothesis import event, given, settings
from hypothesis import strategies as st

from graphloc.cli import main
from graphloc.datasets import open_run
from benchmarks.rosbag_export import KINDS, export_bag
from graphloc.datasets.rosbag_topics import MESSAGE_TYPES
from helpers import EXAMPLES, FAST

DETECTIONS = "/climber/camera/detections"


def _add_scans(root: Path) -> None:
    """Two 30-point scans of a 6 m box for the climber (a PointCloud2 topic in the bag)."""
    manifest = json.loads((root / "manifest.json").read_text())
    climber = next(r for r in manifest["robots"] if r["name"] == "climber")
    climber["sensors"].append({"name": "lidar", "type": "scanner"})
    climber["tables"]["scans"] = "climber/scans.csv"
    (root / "manifest.json").write_text(json.dumps(manifest))
    odometry = (root / "climber/relative_pose3.csv").read_text().splitlines()
    rows, rng = ["time,sensor,path"], np.random.default_rng(0)
    for k, line in enumerate(odometry[1:3]):
        pts = o3d.core.Tensor(rng.uniform(-3.0, 3.0, (30, 3)))
        o3d.t.io.write_point_cloud(str(root / f"climber/s{k}.ply"), o3d.t.geometry.PointCloud(pts))
        rows.append(f"{line.split(',')[0]},lidar,climber/s{k}.ply")
    (root / "climber/scans.csv").write_text("\n".join(rows) + "\n")


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    """kind -> (folder holding the bag and topics.yaml, bag path in it, {topic: (msgtype, n)})."""
    tmp = tmp_path_factory.mktemp("bags")
    assert main(["simulate", "kaushik-p3p-error", "--out", str(tmp / "log")]) == 0
    _add_scans(tmp / "log")
    out = {}
    for kind in KINDS:
        bag = tmp / kind / ("run.bag" if kind == "ros1" else "bag")
        bag.parent.mkdir()
        export_bag(tmp / "log", bag, kind)
        with AnyReader([bag]) as reader:
            topics = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        assert open_run(bag).skips.counts == {}, kind  # the uncorrupted bag reads cleanly
        out[kind] = (tmp / kind, bag.relative_to(tmp / kind), topics)
    return out


def _corrupt(data: bytearray, draw) -> bytes:
    if draw(st.booleans()):  # truncate
        return bytes(data[: draw(st.integers(0, len(data)))])
    for _ in range(draw(st.integers(1, 12))):
        data[draw(st.integers(0, len(data) - 1))] ^= 1 << draw(st.integers(0, 7))
    return bytes(data)


@settings(FAST, max_examples=EXAMPLES or 30)
@given(data=st.data(), kind=st.sampled_from(KINDS))
def test_bag_reader_returns_counted_skips_or_a_value_error_naming_the_bag(
    tmp_path_factory, bags, data, kind
):
    folder, rel, msgs = bags[kind]
    work = tmp_path_factory.mktemp("fuzz")
    shutil.copytree(folder, work / "b")
    bag = work / "b" / rel
    draw = data.draw
    # corrupt one of the bag's files (a ROS 2 bag: its storage file or metadata.yaml)
    files = sorted(p for p in (bag.parent if kind == "ros1" else bag).iterdir() if p.is_file())
    files = [p for p in files if p.name != "topics.yaml"]
    corrupt = draw(st.booleans())
    if corrupt:
        target = draw(st.sampled_from(files))
        target.write_bytes(_corrupt(bytearray(target.read_bytes()), draw))
    # map topics to other topics' messages (a permutation of the topic names)
    topics_file = bag.parent / "topics.yaml" if kind == "ros1" else bag / "topics.yaml"
    tf = yaml.safe_load(topics_file.read_text())
    names = list(tf["topics"])
    permuted = draw(st.permutations(names))
    tf["topics"] = {new: tf["topics"][old] for old, new in zip(names, permuted)}
    no_info = draw(st.integers(0, 3)) == 0
    if no_info:  # the camera's CameraInfo topic is not in the bag
        owner = next(t for t, e in tf["topics"].items() if e["table"] == "markers")
        tf["topics"][owner]["camera_info"] = "/climber/camera/camera_info"
    topics_file.write_text(yaml.safe_dump(tf))
    try:
        run = open_run(bag)
    except ValueError as exc:
        msg = str(exc)
        event("ValueError: " + ("cannot read bag" if "cannot read bag" in msg else msg[-40:]))
        assert str(bag) in msg and "graphloc-bag-" not in msg, msg
        if no_info and not corrupt:
            assert f"topic '{owner}' message 0: no sensor_msgs/msg/CameraInfo" in msg, msg
        elif not corrupt:  # nothing usable left: the import's skips are in the message
            wrong = _wrong_type(tf, msgs)
            assert "(import skipped: " in msg and (not wrong or f"wrong_type {wrong}" in msg), msg
        return
    assert not (no_info and not corrupt)
    event(f"run, skips: {sorted(run.skips.counts)}")
    for example in run.skips.examples:
        assert str(bag) in example and "graphloc-bag-" not in example, example
        assert "reading stopped after" in example or "message " in example, example
    if not corrupt:
        assert run.skips.counts.get("wrong_type", 0) == _wrong_type(tf, msgs)


def _wrong_type(tf: dict, msgs: dict) -> int:
    """Messages of the mapped topics whose type the topic's table does not take."""
    return sum(
        msgs[topic][1]
        for topic, entry in tf["topics"].items()
        if msgs[topic][0] not in MESSAGE_TYPES[entry["table"]]
    )
