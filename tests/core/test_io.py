"""graphloc log format: manifest, typed tables, time-ordered streaming merge, validation errors
naming file / line / field, counted skips, PlanarRun conversion with sensor extrinsics."""

import json

import numpy as np
import pytest

from graphloc.records import (
    Bearing3D,
    GroundTruth2D,
    MarkerPixel,
    Odometry2D,
    PoseCandidate,
    RangeBearing2D,
    ScanRef,
)
from graphloc.textio import SkipReport
from graphloc.io import iter_records
from graphloc.manifest import read_manifest
from graphloc.datasets.graphloc_log import read_team_run
from helpers import make_log


def test_streaming_merge_is_time_ordered_and_typed(tmp_path):
    root = make_log(tmp_path / "log")
    records = list(iter_records(root))
    times = [r.time for r in records]
    assert times == sorted(times) and len(records) == 14
    kinds = {type(r) for r in records}
    assert kinds == {
        Odometry2D,
        RangeBearing2D,
        MarkerPixel,
        PoseCandidate,
        ScanRef,
        GroundTruth2D,
        Bearing3D,
    }
    only = list(iter_records(root, tables=["odometry"]))
    climber = [r.time for r in only if r.robot == "climber"]
    assert climber == [0.1, 0.9] and {type(r) for r in only} == {Odometry2D}
    m = read_manifest(root)
    np.testing.assert_allclose(
        m.robot("ground").sensor("ceilcam").body_T_sensor[:3, 3], [0, 0, 0.2]
    )


@pytest.mark.parametrize(
    "row, message",
    [
        ("0.6,wheels,abc,0.0", r"line 3: field 'v': cannot parse"),
        ("0.6,wheels,nan,0.0", r"line 3: field 'v': nan is not finite"),
        ("0.6,wheels,0.1", r"line 3: expected 4 fields"),
        ("0.1,wheels,0.1,0.0", r"line 3: field 'time': 0.1 goes backwards"),
        ("0.6,gps,0.1,0.0", r"line 3: field 'sensor': robot 'ground' has no sensor 'gps'"),
        ("0.6,cam,0.1,0.0", r"line 3: field 'sensor': 'cam' is a range_bearing"),
    ],
)
def test_bad_rows_raise_with_file_line_field(tmp_path, row, message):
    root = make_log(tmp_path / "log", odo_a=["0.5,wheels,0.1,0.0", row, "1.0,wheels,0.1,0.0"])
    with pytest.raises(ValueError, match=r"ground/odometry\.csv: " + message):
        list(iter_records(root))


def test_bad_rows_are_counted_when_skipping(tmp_path):
    root = make_log(
        tmp_path / "log",
        odo_a=["0.5,wheels,0.1,0.0", "0.6,wheels,inf,0", "0.4,wheels,0,0", "1.0,wheels,0.1,0.0"],
        rb_a=[
            "0.25,cam,landmark:99,1.0,0.0",
            "0.3,cam,robot7,1.0,0.0",
            "0.75,cam,climber,2.0,-1.0",
        ],
    )
    report = SkipReport()
    records = list(iter_records(root, on_error="skip", report=report))
    assert report.counts == {"non_finite": 1, "time_backwards": 1, "unknown_target": 2}
    assert (
        report.total == 4 and len(records) == 12
    )  # of 14: one odometry and one range-bearing row fewer
    assert any("landmark:99" in e for e in report.examples)


def test_manifest_validation(tmp_path):
    root = make_log(tmp_path / "log")
    data = json.loads((root / "manifest.json").read_text())
    data["robots"][0]["tables"]["weather"] = "x.csv"
    (root / "manifest.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match="unknown table 'weather'"):
        read_manifest(root)
    (root / "manifest.json").write_text("{ not json")
    with pytest.raises(ValueError, match="line 1: invalid JSON"):
        read_manifest(root)
    with pytest.raises(FileNotFoundError):
        read_manifest(tmp_path / "nowhere")
    root2 = make_log(tmp_path / "log2")
    (root2 / "ground/odometry.csv").write_text("t,sensor,v,omega\n0,wheels,0,0\n")
    with pytest.raises(ValueError, match="line 1: header must be time,sensor,v,omega"):
        list(iter_records(root2))


def test_team_run_keeps_sensor_extrinsics_and_planar_poses(tmp_path):
    root = make_log(tmp_path / "log")
    data = json.loads((root / "manifest.json").read_text())
    for robot in data[
        "robots"
    ]:  # the graph's tables only (markers need a layout, scans go to fuse-maps)
        robot["tables"] = {
            k: v for k, v in robot["tables"].items() if k not in ("markers", "candidates", "scans")
        }
    (root / "manifest.json").write_text(json.dumps(data))
    run = read_team_run(root)
    assert [r.name for r in run.robots] == ["ground", "climber"] and run.skips.total == 0
    assert [r.planar for r in run.robots] == [
        True,
        False,
    ]  # version 2 default: kind ground is planar
    # cam at (0.1, 0) yawed +90 deg: 1 m along the camera axis is (0.1, 1.0) in the body frame
    m = next(p for p in run.points if p.landmark == 3)
    np.testing.assert_allclose(
        m.body_T_sensor.transformFrom(m.direction * m.range), [0.1, 1.0, 0.0], atol=1e-12
    )
    assert next(p for p in run.points if p.kind == "range_bearing" and p.target >= 0).target == 1
    np.testing.assert_allclose(run.robots[1].initial_pose.translation(), [1, 0, 0])
    assert run.groundtruth[1] is None and len(run.groundtruth[0][0]) == 2


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: [], "must be a JSON object"),
        (lambda d: {**d, "robots": {"ground": 1}}, "field 'robots' must be a JSON list"),
        (lambda d: {**d, "robots": [{**d["robots"][0], "initial_pose": 5}]}, "initial_pose"),
        (
            lambda d: {**d, "robots": [{**d["robots"][0], "sensors": ["cam"]}]},
            r"sensors\[0\]: fields 'name' and 'type'",
        ),
    ],
)
def test_malformed_manifest_types_are_clear_errors(tmp_path, edit, message):
    root = make_log(tmp_path / "log")
    data = json.loads((root / "manifest.json").read_text())
    (root / "manifest.json").write_text(json.dumps(edit(data)))
    with pytest.raises(ValueError, match=message):
        read_manifest(root)


def test_log_without_landmarks_file_keeps_landmark_observations(tmp_path):
    """SLAM logs (landmark positions unknown) have no landmarks.csv: their landmark measurements
    must still be read, not skipped as unknown targets."""
    root = make_log(tmp_path / "log")
    data = json.loads((root / "manifest.json").read_text())
    del data["landmarks"]
    (root / "manifest.json").write_text(json.dumps(data))
    (root / "landmarks.csv").unlink()
    report = SkipReport()
    records = list(iter_records(root, tables=["range_bearing"], on_error="skip", report=report))
    assert any(getattr(r, "target", "") == "landmark:3" for r in records)
    assert report.total == 0
