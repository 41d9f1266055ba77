"""A bare directory of scans as a run (issue 13; datasets/scan_directory.py): the ground robot's
ray-cast scans of `graphloc simulate dual-robot-room`, copied into a plain folder (as .ply, as
KITTI .bin, with and without times.txt) -> `graphloc.datasets.open_run` -> `graphloc smooth
DIR` gives KISS-ICP's trajectory over the same files; bad times files and scans are errors
naming the user's file, line and field."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from graphloc.cli import main
from graphloc.datasets import open_run
from graphloc.mapping.io import read_scan_sequence
from graphloc.mapping.odometry import run_odometry

RATE = 5.0  # the simulated scanner's rate [Hz] (its scans.csv: 0.2 s apart)


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("room")
    assert main(["simulate", "dual-robot-room", "--out", str(tmp / "run")]) == 0
    return tmp / "run"


def _scans(room: Path, dst: Path) -> Path:
    shutil.copytree(room / "scans/ground", dst)
    return dst


def _pose_matrices(rows: np.ndarray) -> np.ndarray:
    T = np.tile(np.eye(4), (len(rows), 1, 1))
    T[:, :3, :3] = Rotation.from_quat(rows[:, 4:8]).as_matrix()
    T[:, :3, 3] = rows[:, 1:4]
    return T


def test_smooth_scan_directory_is_kiss_icp(room, tmp_path, capsys):
    scans = _scans(room, tmp_path / "scans")
    files = sorted(p.name for p in scans.iterdir())
    assert len(files) > 3
    run = open_run(scans, source={"scan_rate": RATE})
    assert [r.name for r in run.robots] == ["scanner"]
    assert len(run.motions) == len(files) - 1 and len(run.scans) == len(files)
    assert [Path(s.path).name for s in run.scans] == files  # sorted by name, in time order
    out = tmp_path / "out"
    argv = ["smooth", str(scans), "--scan-rate", str(RATE), "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    est = np.loadtxt(out / "scanner_batch.tum", ndmin=2)
    np.testing.assert_allclose(est[:, 0], np.arange(len(files)) / RATE, atol=1e-9)
    kiss = run_odometry(read_scan_sequence(scans)[0]).poses  # the same files, KISS-ICP directly
    T = _pose_matrices(est)
    assert np.abs(T[:, :3, 3] - kiss[:, :3, 3]).max() < 1e-6
    assert np.abs(T[:, :3, :3] - kiss[:, :3, :3]).max() < 1e-6
    # and KISS-ICP follows the simulated robot: the truth's motion since its first pose
    truth = np.loadtxt(room / "poses_ground.tum", ndmin=2)[: len(files)]
    G = np.linalg.inv(_pose_matrices(truth[:1])[0]) @ _pose_matrices(truth)
    assert np.linalg.norm(G[-1, :3, 3]) > 0.2 and np.abs(T[:, :3, 3] - G[:, :3, 3]).max() < 0.05
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["options"]["scan_rate"] == RATE


def test_times_file_and_kitti_bin(room, tmp_path):
    """times.txt gives the stamps; the same scans as KITTI .bin (float32) give the same
    trajectory to float32 precision; the default rate is 10 Hz."""
    scans = _scans(room, tmp_path / "ply")
    n = len(list(scans.iterdir()))
    assert [m.t1 for m in open_run(scans).motions] == pytest.approx(np.arange(1, n) / 10.0)
    stamps = 1700000000.0 + np.cumsum(np.r_[0.0, np.full(n - 1, 0.1)])
    (scans / "times.txt").write_text("# KITTI style\n" + "".join(f"{t:.6f}\n" for t in stamps))
    run = open_run(scans)
    assert [m.t1 for m in run.motions] == pytest.approx(stamps[1:], abs=1e-6)
    kitti = tmp_path / "kitti"
    kitti.mkdir()
    for k, scan in enumerate(read_scan_sequence(scans)[0]):
        xyzi = np.column_stack([scan, np.zeros(len(scan))]).astype("<f4")
        xyzi.tofile(kitti / f"{k:06d}.bin")
    bins = open_run(kitti)
    a = np.array([m.relative.translation() for m in run.motions])
    b = np.array([m.relative.translation() for m in bins.motions])
    assert len(b) == n - 1 and np.abs(a - b).max() < 1e-3


def test_bad_inputs_name_the_file(room, tmp_path, capsys):
    scans = _scans(room, tmp_path / "scans")
    out = ["--out", str(tmp_path / "out"), "--no-progress"]
    n = len(list(scans.iterdir()))
    (scans / "times.txt").write_text("0.0\n0.1\nabc\n")
    assert main(["smooth", str(scans)] + out) == 2
    assert f"{scans / 'times.txt'}: line 3: field 'time': 'abc' is not a number" in (
        capsys.readouterr().err
    )
    (scans / "times.txt").write_text("0.0\n0.1\n0.1\n")
    assert main(["validate", str(scans)]) == 2
    assert "line 3: field 'time': 0.1 is not after the previous time 0.1" in (
        capsys.readouterr().err
    )
    (scans / "times.txt").write_text("0.0\n0.1\n")
    assert main(["validate", str(scans)]) == 2
    assert f"times.txt: 2 times for {n} scans" in capsys.readouterr().err
    (scans / "times.txt").unlink()
    bad = scans / "000003.ply"
    bad.write_text("ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nend_header\n1\n")
    assert main(["validate", str(scans)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "graphloc-scans-" not in err, err
    bad.unlink()
    (scans / "000009.bin").write_bytes(b"\0" * 20)
    assert main(["validate", str(scans)]) == 2
    assert f"{scans / '000009.bin'}: 20 bytes is not a whole number" in capsys.readouterr().err
    (scans / "000009.bin").unlink()
    assert main(["validate", str(scans), "--scan-rate", "0"]) == 2
    assert "scan_rate" in capsys.readouterr().err
    assert main(["validate", str(scans), "--topics", str(tmp_path / "t.yaml")]) == 2
    assert "--topics does not apply to a scan-directory source" in capsys.readouterr().err
    assert main(["validate", str(room), "--scan-rate", "5"]) == 2
    assert "--scan-rate does not apply to a graphloc-log source" in capsys.readouterr().err
