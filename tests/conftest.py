"""Fixtures shared by the test modules: small valid runs written once per session and copied
for each test that breaks them, and the command line run in-process with the checks every
bad-input test makes (no traceback, a documented exit code, no file written outside `--out`).
Fixtures of one folder are in its own conftest.py (tests/live/: ROS 2 on the loopback).
Plain functions the test modules share (writers of small inputs, hypothesis settings) are in
tests/helpers.py, the simulated bags in tests/helpers_bags.py and the live route's
comparisons in tests/helpers_live.py.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest

from graphloc import exitcodes
from helpers import scan_dirs, write_planar_log, write_tiny_mrclam

DOCUMENTED_CODES = set(exitcodes.CODES)


# ---- runs written once, copied per test -------------------------------------------------------
@pytest.fixture(scope="session")
def planar_log_template(tmp_path_factory) -> Path:
    """A valid planar log (two robots, wheel odometry, range-bearing to two landmarks, planar
    ground truth; the tiny MRCLAM run of helpers.write_tiny_mrclam through the MRCLAM reader)."""
    return write_planar_log(tmp_path_factory.mktemp("planar"))


@pytest.fixture(scope="session")
def mrclam_template(tmp_path_factory) -> Path:
    """The tiny MRCLAM directory itself (RobotN_*.dat, Barcodes.dat, landmarks)."""
    root = tmp_path_factory.mktemp("mrclam") / "mr"
    write_tiny_mrclam(root)
    return root


@pytest.fixture(scope="session")
def camera_log_template(tmp_path_factory) -> Path:
    """A valid 3D log with a camera: `graphloc simulate feng-probabilistic` (a climber's
    relative_pose3 odometry and marker pixels of a static ground robot, TUM ground truth)."""
    from graphloc.cli import main

    out = tmp_path_factory.mktemp("camera") / "feng"
    assert main(["simulate", "feng-probabilistic", "--out", str(out), "-q"]) == 0
    return out


@pytest.fixture(scope="session")
def bag_template(tmp_path_factory) -> Path:
    """A folder with a ROS 1 bag `run.bag` (a rover's odometry, ground truth and UWB ranges to
    three beacons; receive times jitter, so bag order differs from the stamps' order) and its
    topics file `topics.yaml` (tests/datasets/test_rosbag.py)."""
    import yaml
    from helpers_bags import TOPICS, simulate, write_bag

    folder = tmp_path_factory.mktemp("bag") / "bag"
    folder.mkdir()
    write_bag(simulate(), folder / "run.bag", "ros1")
    (folder / "topics.yaml").write_text(yaml.safe_dump(TOPICS))
    return folder


@pytest.fixture(scope="session")
def checkpoint_template(tmp_path_factory, planar_log_template) -> Path:
    """An online checkpoint of the planar log (`graphloc online --checkpoint`, every 5 steps)."""
    from graphloc.cli import main

    tmp = tmp_path_factory.mktemp("checkpoint")
    argv = ["online", str(planar_log_template), "--out", str(tmp / "out"), "-q"]
    argv += ["--checkpoint", str(tmp / "run.ckpt"), "--checkpoint-every", "5"]
    assert main(argv) == 0
    return tmp / "run.ckpt"


@pytest.fixture(scope="session")
def scan_dirs_template(tmp_path_factory) -> Path:
    """`ground/` and `ceiling/`: two scans each of 400 points on the walls of a 6 x 4 x 3 m room
    (helpers.scan_dirs), the inputs of `fuse-maps --ground --ceiling`."""
    root = tmp_path_factory.mktemp("scans") / "scans"
    scan_dirs(root)
    return root


def _copy(template: Path, tmp_path: Path, name: str) -> Path:
    dest = tmp_path / "in" / name
    shutil.copytree(template, dest, symlinks=True)
    return dest


@pytest.fixture
def planar_log(planar_log_template, tmp_path) -> Path:
    return _copy(planar_log_template, tmp_path, "log")


@pytest.fixture
def mrclam_dir(mrclam_template, tmp_path) -> Path:
    return _copy(mrclam_template, tmp_path, "mr")


@pytest.fixture
def camera_log(camera_log_template, tmp_path) -> Path:
    return _copy(camera_log_template, tmp_path, "feng")


@pytest.fixture
def bag_dir(bag_template, tmp_path) -> Path:
    return _copy(bag_template, tmp_path, "bag")


@pytest.fixture
def scans(scan_dirs_template, tmp_path) -> Path:
    return _copy(scan_dirs_template, tmp_path, "scans")


# ---- the command line, in-process -------------------------------------------------------------
@dataclass
class CliResult:
    code: int
    out: str
    err: str

    @property
    def error_line(self) -> str:
        lines = [line for line in self.err.splitlines() if ": error: " in line]
        return lines[0] if lines else ""

    def json(self) -> dict:
        return json.loads(self.out)


def _tree(root: Path, skip: Path | None, allow=()) -> dict:
    """{relative path: (size, mtime_ns)} of every file under `root` outside the folder `skip`
    and other than the files `allow`."""
    out = {}
    for p in sorted(root.rglob("*")):
        if skip is not None and (p == skip or skip in p.parents):
            continue
        if p in allow:
            continue
        if p.is_file() and not p.is_symlink():
            st = p.stat()
            out[str(p.relative_to(root))] = (st.st_size, st.st_mtime_ns)
    return out


@pytest.fixture
def cli(tmp_path, capsys, monkeypatch):
    """Run `graphloc ARGV` in-process from an empty working directory inside tmp_path and
    check what every verb promises whatever its input: no traceback, an exit code of
    docs/outputs.md, and no file created or changed in tmp_path outside the folder `out`
    (none at all without it) but the files `allow` (e.g. a checkpoint). Returns a
    CliResult."""
    from graphloc.cli import main

    cwd = tmp_path / "cwd"
    cwd.mkdir(exist_ok=True)
    monkeypatch.chdir(cwd)

    def run(argv, out: Path | None = None, allow=()) -> CliResult:
        keep = [Path(a) for a in allow]
        before = _tree(tmp_path, out, keep)
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse's usage errors
            code = exc.code if isinstance(exc.code, int) else exitcodes.BAD_INPUT
        got = capsys.readouterr()
        result = CliResult(code, got.out, got.err)
        assert "Traceback" not in got.out + got.err, got.err[-3000:]
        assert code in DOCUMENTED_CODES, (code, got.err[-2000:])
        if code == exitcodes.BAD_INPUT:
            assert result.error_line or "usage:" in got.err, got.err[-2000:]
        after = _tree(tmp_path, out, keep)
        assert after == before, sorted(set(after.items()) ^ set(before.items()))[:10]
        return result

    return run
