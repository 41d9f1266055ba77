"""The loopback test of issue 50: three processes on Cyclone DDS over the loopback interface
only (a domain of this test alone). One publishes the bundled Husky bag's wheel odometry as ROS
2 topics at 20 times its recorded pace (`scripts/publish_bag_ros2.py`), `graphloc live --ros2
--publish` subscribes and publishes poses, and this process reads them back and checks them
against `graphloc online` on the same bag (`graphloc import`, then online): every step's pose as
`online` estimated it right after that step (its causal estimate), and the final outputs."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

import graphloc
from graphloc.cli import main

from helpers_bags import REAL_BAG

ROOT = Path(__file__).resolve().parents[2]
ODOM = "/husky_velocity_controller/odom"
TOPICS = {
    "name": "husky-outdoor",
    "robots": [
        {
            "name": "husky",
            "kind": "ground",
            "initial_pose": [0.0, 0.0, 0.0],
            "sensors": [{"name": "wheels", "type": "odometry"}],
        }
    ],
    # the Odometry messages' twist: unicycle velocities (forward speed, yaw rate)
    "topics": {ODOM: {"robot": "husky", "table": "odometry", "sensor": "wheels"}},
}


@pytest.mark.slow  # ~35 s: three processes start GTSAM and Cyclone DDS
def test_bag_over_ros2_through_graphloc_live_is_graphloc_online(loopback, tmp_path):  # noqa: F811
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from graphloc.live.ros2 import KEEP_POSES, POSE_TYPE, participant, qos
    from graphloc.live.ros2_types import dds_topic, idl_type

    topics = tmp_path / "topics.yaml"
    topics.write_text(yaml.safe_dump(TOPICS))
    dp = participant()  # the third process's reader: transient-local, so it misses no pose
    reader = DataReader(
        dp, Topic(dp, dds_topic("/husky/pose"), idl_type(POSE_TYPE)), qos=qos(KEEP_POSES)
    )
    out = tmp_path / "live"
    exe = Path(sys.executable).parent / "graphloc"
    live = subprocess.Popen(
        [exe, "live", "--ros2", "--topics", topics, "--out", out, "--publish", "--idle", "3"]
        + ["--no-progress"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    script = ROOT / "scripts/publish_bag_ros2.py"
    argv = [sys.executable, script, REAL_BAG, "--topics", topics, "--rate", "20", "--wait", "120"]
    pub = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert pub.returncode == 0, pub.stderr
    assert "published 1200 messages on 1 topics" in pub.stdout
    stdout, stderr = live.communicate(timeout=300)
    assert live.returncode == 0, stderr
    got, end = [], time.monotonic() + 10
    while time.monotonic() < end and len(got) < 480:
        got += [s for s in reader.take(N=10000) if hasattr(s, "header")]
        time.sleep(0.05)
    got += [s for s in reader.take(N=10000) if hasattr(s, "header")]  # none more
    # the reference: the bag imported, then graphloc online
    assert (
        main(["import", str(REAL_BAG), "--topics", str(topics), "--out", str(tmp_path / "log")])
        == 0
    )
    ref = graphloc.run_team(tmp_path / "log", tmp_path / "online", "online").result
    times, causal = ref.node_times[0], ref.causal[0]
    assert len(got) == len(times) == 480
    stamps = np.array([s.header.stamp.sec + s.header.stamp.nanosec * 1e-9 for s in got])
    np.testing.assert_allclose(stamps, times, rtol=0, atol=1e-9)
    xyz = np.array(
        [[s.pose.pose.position.x, s.pose.pose.position.y, s.pose.pose.position.z] for s in got]
    )
    assert np.abs(xyz - causal[:, :3]).max() < 1e-9
    assert np.all([np.isfinite(s.pose.covariance).all() for s in got])
    a = np.loadtxt(out / "husky_online.tum")
    b = np.loadtxt(tmp_path / "online" / "husky_online.tum")
    assert a.shape == b.shape and np.abs(a - b).max() < 1e-9
    # what arrived was recorded: OUT/log is the imported log's odometry table, row for row
    np.testing.assert_array_equal(
        np.loadtxt(out / "log/husky/odometry.csv", delimiter=",", skiprows=1, usecols=(0, 2, 3)),
        np.loadtxt(
            tmp_path / "log/husky/odometry.csv", delimiter=",", skiprows=1, usecols=(0, 2, 3)
        ),
    )
