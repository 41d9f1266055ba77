"""A bare directory of scans (`.ply`, `.pcd`, `.xyz`, KITTI `.bin`; times from `times.txt` or a
rate) as a one-robot run (issue 13), as KISS-ICP's generic dataloader reads it: written as a
log in a temporary directory and read like any log's scans."""

from __future__ import annotations

import atexit
import os
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np

from graphloc.datasets.graphloc_log import read_team_run
from graphloc.manifest import write_manifest
from graphloc.log_writer import write_table
from graphloc.names import out_path, safe_name
from graphloc.run import TeamRun, truncate
from graphloc.textio import check_file, text_lines

NATIVE = (".ply", ".pcd", ".xyz")  # what Open3D reads (graphloc.mapping.io.SCAN_SUFFIXES)
KITTI = ".bin"
SUFFIXES = NATIVE + (KITTI,)
TIMES_FILE = "times.txt"
DEFAULT_RATE = 10.0  # Hz: KITTI's and most spinning LiDARs' frame rate
ROBOT, SENSOR = "scanner", "lidar"


def scan_files(path) -> list[Path]:
    """The scans of a directory: files with a supported suffix, sorted by name."""
    path = Path(path)
    return sorted(
        (p for p in path.iterdir() if p.suffix.lower() in SUFFIXES and p.is_file()),
        key=lambda p: p.name,
    )


def read_times(path: Path, n: int) -> np.ndarray:
    """(n,) strictly increasing finite times of a times file; ValueError naming file, line and
    field otherwise, or the count when it is not one per scan."""
    check_file(path, what="times file")
    times = []
    for line, text in text_lines(path):
        text = text.split("#", 1)[0].strip()
        if not text:
            continue
        where = f"{path}: line {line}: field 'time'"
        try:
            t = float(text)
        except ValueError:
            raise ValueError(f"{where}: {text!r} is not a number") from None
        if not np.isfinite(t):
            raise ValueError(f"{where}: {text!r} is not finite")
        if times and not t > times[-1]:
            raise ValueError(f"{where}: {t!r} is not after the previous time {times[-1]!r}")
        times.append(t)
    if len(times) != n:
        raise ValueError(f"{path}: {len(times)} times for {n} scans (one time per scan)")
    return np.asarray(times)


def read_kitti_bin(path: Path) -> np.ndarray:
    """(N,3) float64 points of a KITTI velodyne `.bin` file (float32 x y z intensity)."""
    check_file(path, what="point cloud")
    size = path.stat().st_size
    if size == 0 or size % 16:
        raise ValueError(
            f"{path}: {size} bytes is not a whole number of KITTI points "
            "(16-byte float32 x y z intensity records)"
        )
    return np.fromfile(path, dtype="<f4").reshape(-1, 4)[:, :3].astype(np.float64)


def _place(src: Path, dst: Path) -> None:
    """The scan `src` at `dst` in the log directory: a hard link, else a copy; `.bin` -> PLY."""
    if src.suffix.lower() == KITTI:
        import open3d as o3d

        cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(read_kitti_bin(src)))
        if not o3d.t.io.write_point_cloud(str(dst), cloud):
            raise OSError(f"{dst}: cannot write the scan converted from {src}")
        return
    try:
        os.link(src, dst)
    except OSError:
        shutil.copyfile(src, dst)


def write_log(path: Path, out: Path, rate: float | None = None) -> list[Path]:
    """The scan directory `path` as a log directory `out`; returns the scans in order."""
    files = scan_files(path)
    if not files:
        raise ValueError(f"{path}: no {'/'.join(SUFFIXES)} scans")
    if (path / TIMES_FILE).exists():
        times = read_times(path / TIMES_FILE, len(files))
    else:
        rate = DEFAULT_RATE if rate is None else float(rate)
        if not (np.isfinite(rate) and rate > 0):
            raise ValueError(f"scan_rate must be a finite number > 0 [Hz], got {rate!r}")
        times = np.arange(len(files)) / rate
    (out / "scans").mkdir(parents=True, exist_ok=True)
    rows = []
    for t, src in zip(times, files):
        rel = f"scans/{src.name}" + (".ply" if src.suffix.lower() == KITTI else "")
        _place(src, out_path(out, *rel.split("/")))
        rows.append((float(t), SENSOR, rel))
    write_table(out / "scans.csv", "scans", rows)
    robot = {
        "name": ROBOT,
        "kind": "handheld",
        "planar": False,
        "initial_pose": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        "sensors": [{"name": SENSOR, "type": "scanner"}],
        "tables": {"scans": "scans.csv"},
    }
    source = "times file" if (path / TIMES_FILE).exists() else f"index at {rate:g} Hz"
    body = {
        "name": safe_name(path.resolve().name, "scans"),
        "start_time": float(times[0]),
        "robots": [robot],
        "meta": {"scan_directory": {"source": str(path), "times": source}},
    }
    write_manifest(body, out)
    return files


class ScanDirectory:
    """A directory of `.ply` / `.pcd` / `.xyz` / KITTI `.bin` scans (with an optional
    `times.txt`): one robot `scanner` whose motion is KISS-ICP odometry over the scans."""

    name = "scan-directory"
    expects = f"a directory of {'/'.join(SUFFIXES)} scans (optional {TIMES_FILE})"
    options = ("scan_rate",)

    def matches(self, path: Path) -> bool:
        return path.is_dir() and bool(scan_files(path))

    def load(
        self, path: Path, duration: float | None, noise: dict | None, scan_rate=None
    ) -> TeamRun:
        tmp = Path(tempfile.mkdtemp(prefix="graphloc-scans-"))
        run = None
        try:
            write_log(path, tmp, scan_rate)
            run = read_team_run(tmp, overrides=noise)
        except (OSError, ValueError) as exc:  # name the user's files, not the copies
            msg = re.sub(r"^\S*scans\.csv: line \d+: field 'path': ", "", str(exc))
            raise type(exc)(msg.replace(str(tmp / "scans"), str(path))) from None
        finally:
            if run is None:
                shutil.rmtree(tmp, ignore_errors=True)
        # the team graph reads the scans again (registration): kept until exit
        atexit.register(shutil.rmtree, tmp, ignore_errors=True)
        return run if duration is None else truncate(run, duration)
