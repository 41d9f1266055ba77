"""Files of the mapping pipeline: read a scan (PLY / PCD / XYZ) as an (N,3) array (`read_scan`,
checked for a plausible scale; `check_scan_units`: robots' sequences in one unit), write a fused
map whose points carry the robot that saw them, and SE(3) trajectories as TUM files. Sizes
(docs/log_format.md, "Scan files"): a file over MAX_SCAN_BYTES or MAX_SCAN_POINTS is refused
before it is read; a scan over POINT_BUDGET points is thinned on read (`thin_to_budget`,
seeded), counted as `scan_thinned` in the caller's notes."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import open3d as o3d

from graphloc.names import written_whole
from graphloc.mapping.cloud_files import open3d_points, pcd_check, ply_check, xyz_points
from graphloc.textio import check_file, csv_fields, shown, text_lines

SCAN_SUFFIXES = (".ply", ".pcd", ".xyz")
MAX_COORDINATE = 1e6  # m: beyond, a point cloud is not in metres (or overflowed)
MIN_POINTS = 10  # finite points per scan
SCAN_RANGE_M = (0.05, 500.0)  # plausible median range of one LiDAR / depth scan [m]
# largest plausible ratio of two scales (robust extents) that should agree: one robot's scans
# over the other's, or one scan over its sequence. A unit mismatch is a factor 39.4 (inches),
# 100 (centimetres) or 1000 (millimetres); two sensors in the same room differ by a few.
MAX_SCALE_RATIO = 20.0
UNIT_FACTORS = {"inches": 39.37, "centimetres": 100.0, "millimetres": 1000.0}
ROBOT_COLOURS = np.array([[0.85, 0.15, 0.1], [0.1, 0.3, 0.9], [0.1, 0.7, 0.2], [0.6, 0.2, 0.7]])
MAX_SCAN_BYTES = 2 << 30  # a scan file larger is refused before it is read
MAX_SCAN_POINTS = 20_000_000  # points a scan file may declare (PLY / PCD header, XYZ lines)
POINT_BUDGET = 500_000  # points of one scan kept on read; a denser scan is thinned at random
LOG = logging.getLogger("graphloc.scans")


def read_points(path) -> np.ndarray:
    """(N,3) float64 points of one scan file; ValueError naming the file if it is not a readable
    regular file, its data do not match its PLY / PCD header or an XYZ row is not three numbers
    (`graphloc.mapping.cloud_files`), it holds no points (Open3D's failed parse of a garbage
    file included) or points beyond +-MAX_COORDINATE (NaN returns are a counted skip only in
    `read_scan_sequence`)."""
    path = Path(path)
    if path.suffix.lower() not in SCAN_SUFFIXES:
        raise ValueError(f"{path}: unsupported point cloud suffix (use {', '.join(SCAN_SUFFIXES)})")
    check_file(path, what="point cloud")
    size = path.stat().st_size
    if size > MAX_SCAN_BYTES:
        raise ValueError(
            f"{path}: {size} bytes, beyond the limit of {MAX_SCAN_BYTES} bytes for one scan "
            f"(graphloc.mapping.io.MAX_SCAN_BYTES); split or thin the cloud first"
        )
    suffix = path.suffix.lower()
    limit = MAX_SCAN_POINTS
    declared = (
        ply_check(path, limit)
        if suffix == ".ply"
        else pcd_check(path, limit)
        if suffix == ".pcd"
        else None
    )
    pts = xyz_points(path, MAX_SCAN_POINTS) if suffix == ".xyz" else open3d_points(path)
    if len(pts) == 0:
        raise ValueError(f"{path}: no points could be read (not a {path.suffix} point cloud?)")
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"{path}: positions have shape {pts.shape}, expected (N,3)")
    if suffix == ".ply" and declared != len(pts):
        raise ValueError(
            f"{path}: truncated or corrupt: the PLY header declares {declared} vertices, "
            f"{len(pts)} could be read"
        )
    finite = pts[np.isfinite(pts).all(axis=1)]
    if len(finite) and np.abs(finite).max() > MAX_COORDINATE:
        raise ValueError(
            f"{path}: coordinates up to {np.abs(finite).max():.3g}, beyond +-{MAX_COORDINATE:g} m: "
            f"not a scan in metres"
        )
    return pts


def read_scan_sequence(folder, notes=None) -> tuple[list[np.ndarray], list[Path], int]:
    """All scans of a folder in file-name order, each checked by `read_scan` (non-finite points
    dropped and counted; a scan beyond POINT_BUDGET thinned, counted in `notes`, a
    `graphloc.textio.SkipReport`). Returns (scans, files, n_dropped_nonfinite)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: not a directory of scans")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in SCAN_SUFFIXES)
    if len(files) == 0:
        raise ValueError(f"{folder}: no {'/'.join(SCAN_SUFFIXES)} scans")
    scans, dropped = [], 0
    for p in files:
        pts, n = read_scan(p, notes)
        scans.append(pts)
        dropped += n
    return scans, files, dropped


def read_scan(path, notes=None, warn: bool = True) -> tuple[np.ndarray, int]:
    """One scan in metres in its sensor's frame (`read_points`): its finite points (thinned to
    POINT_BUDGET, `thin_to_budget`, counted in `notes` when given) and how many non-finite ones
    (no return) were dropped. ValueError naming the file unless it has at least MIN_POINTS
    finite points, not all within 1 mm of each other, with a median range (distance from the
    sensor) within SCAN_RANGE_M -- a scan in millimetres (a room's median range in the
    thousands) or kilometres is caught here, before any registration."""
    pts = read_points(path)
    ok = np.isfinite(pts).all(axis=1)
    pts = thin_to_budget(pts[ok], path, notes, warn=warn)
    if len(pts) < MIN_POINTS:
        raise ValueError(f"{path}: {len(pts)} finite points, at least {MIN_POINTS} needed")
    if np.ptp(pts, axis=0).max() < 1e-3:
        raise ValueError(f"{path}: all {len(pts)} points lie within 1 mm of each other")
    median = float(np.median(np.linalg.norm(pts, axis=1)))
    lo, hi = SCAN_RANGE_M
    if not lo <= median <= hi:
        unit = "millimetres" if median > hi else "kilometres"
        raise ValueError(
            f"{path}: median range {median:.4g} is outside the plausible [{lo:g}, {hi:g}] m of a "
            f"scan in metres (in {unit}?); convert the scans to metres"
        )
    return pts, int((~ok).sum())


def thin_to_budget(
    pts: np.ndarray, path, notes=None, budget: int | None = None, warn: bool = True
) -> np.ndarray:
    """`pts` if it has at most `budget` (POINT_BUDGET) points, else `budget` of them drawn at
    random without replacement (a generator seeded by the point count, so one file always gives
    the same points; kept in file order), with a warning naming the file on the terminal
    (unless `warn` is False: a file read again) and the points removed counted as
    `scan_thinned` in `notes`."""
    budget = POINT_BUDGET if budget is None else int(budget)
    if len(pts) <= budget:
        return pts
    keep = np.sort(np.random.default_rng(len(pts)).choice(len(pts), budget, replace=False))
    removed = len(pts) - budget
    message = (
        f"{path}: {len(pts)} points, thinned at random to the budget of {budget} "
        f"(graphloc.mapping.io.POINT_BUDGET)"
    )
    if warn:
        LOG.warning("%s", message)
    if notes is not None:
        notes.add("scan_thinned", message, removed)
    return pts[keep]


def scan_extent(pts: np.ndarray) -> float:
    """Robust size of one scan [m]: the diagonal of its 5th-95th percentile bounding box (a few
    stray returns do not change it; a change of unit scales it by the unit's factor)."""
    lo, hi = np.percentile(pts, [5.0, 95.0], axis=0)
    return float(np.linalg.norm(hi - lo))


def _likely_unit(ratio: float) -> str:
    """The unit whose factor is within 2x of `ratio` (or of 1/ratio), as a hint."""
    r = max(ratio, 1.0 / ratio)
    unit, factor = min(UNIT_FACTORS.items(), key=lambda kv: abs(np.log(r / kv[1])))
    if abs(np.log(r / factor)) < np.log(2.0):
        return f"ratio near {factor:g}: {unit}?"
    return "no common unit factor"


def _sequence_scale(name: str, scans: list, files: list) -> tuple[float, int]:
    """The median extent of one robot's scans and the index of the scan nearest to it;
    ValueError naming the file of a scan whose extent is MAX_SCALE_RATIO off the median."""
    ext = np.maximum([scan_extent(p) for p in scans], 1e-9)
    med = float(np.median(ext))
    ratio = ext / med
    odd = np.flatnonzero((ratio > MAX_SCALE_RATIO) | (ratio < 1.0 / MAX_SCALE_RATIO))
    if len(odd):
        k = int(odd[np.argmax(np.abs(np.log(ratio[odd])))])
        raise ValueError(
            f"{files[k]}: extent {ext[k]:.4g} is {ratio[k]:.3g} x the median {med:.4g} of the "
            f"{len(scans)} {name} scans (beyond {MAX_SCALE_RATIO:g}x): a scan in another unit "
            f"({_likely_unit(ratio[k])})"
        )
    return med, int(np.argmin(np.abs(ext - med)))


def check_scan_units(sequences: dict) -> dict:
    """Before registration: robots' scans (`read_scan` outputs, metres in each sensor's frame;
    `sequences`: name -> (scans, files)) must be in one unit. Compares the robust extent
    (`scan_extent`) of every scan with its sequence's median, then the sequences' medians: a
    ratio beyond MAX_SCALE_RATIO (ceiling scans in millimetres or centimetres beside ground scans
    in metres) is a ValueError naming a file of the largest and of the smallest, both extents,
    the ratio and the unit it suggests. The median range (sensor to point) of each sequence is
    reported beside it. Nearest-neighbour spacing is not compared: it follows the sensors'
    densities, not only their units. Returns the scales for a report."""
    scale = {name: _sequence_scale(name, *seq) for name, seq in sequences.items()}
    hi = max(scale, key=lambda n: scale[n][0])
    lo = min(scale, key=lambda n: scale[n][0])
    ratio = scale[hi][0] / scale[lo][0]
    if ratio > MAX_SCALE_RATIO:
        (med_hi, k_hi), (med_lo, k_lo) = scale[hi], scale[lo]
        raise ValueError(
            f"{sequences[hi][1][k_hi]} and {sequences[lo][1][k_lo]}: the {hi} scans' extent "
            f"(median {med_hi:.4g} over {len(sequences[hi][0])} scans) is {ratio:.3g} x the "
            f"{lo} scans' ({med_lo:.4g} over {len(sequences[lo][0])}), beyond "
            f"{MAX_SCALE_RATIO:g}x: the robots' scans are not in one unit "
            f"({_likely_unit(ratio)}); convert all to metres"
        )

    def ranges(scans):
        return float(np.median([np.median(np.linalg.norm(p, axis=1)) for p in scans]))

    return {
        "extent_m": {name: med for name, (med, _) in scale.items()},
        "median_range_m": {name: ranges(seq[0]) for name, seq in sequences.items()},
        "largest_over_smallest": ratio,
        "max_ratio": MAX_SCALE_RATIO,
    }


def write_labelled_cloud(path, points: np.ndarray, robot: np.ndarray) -> None:
    """Write (N,3) points with an integer per-point `robot` label and a uint8 RGB colour per robot
    to PLY or PCD."""
    path = Path(path)
    if path.suffix.lower() not in (".ply", ".pcd"):
        raise ValueError(f"{path}: fused maps are written as .ply or .pcd")
    points = np.asarray(points, dtype=np.float32)
    robot = np.asarray(robot, dtype=np.int32).reshape(-1, 1)
    if points.ndim != 2 or points.shape[1] != 3 or len(robot) != len(points):
        raise ValueError(
            f"write_labelled_cloud: points {points.shape} / labels {robot.shape} mismatch"
        )
    pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(points))
    rgb = np.round(255.0 * ROBOT_COLOURS[robot[:, 0] % len(ROBOT_COLOURS)]).astype(np.uint8)
    pcd.point.colors = o3d.core.Tensor(rgb)  # uint8: PLY viewers expect 0-255 (uchar r/g/b)
    pcd.point.robot = o3d.core.Tensor(robot)
    path.parent.mkdir(parents=True, exist_ok=True)
    with written_whole(path) as tmp:
        if not o3d.t.io.write_point_cloud(str(tmp), pcd):
            raise ValueError(f"{path}: Open3D could not write the point cloud")


def read_labelled_cloud(path) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of `write_labelled_cloud`: (N,3) points and (N,) robot labels."""
    pcd = o3d.t.io.read_point_cloud(str(path))
    if "robot" not in pcd.point:
        raise ValueError(f"{path}: no per-point 'robot' attribute")
    return pcd.point.positions.numpy().astype(float), pcd.point.robot.numpy().reshape(-1).astype(
        int
    )


def read_tum(path) -> tuple[np.ndarray, np.ndarray]:
    """(F,) times and (F,4,4) poses of a TUM file (graphloc.eval.read_tum / evo); ValueError naming
    the file on malformed rows, non-finite values or time going backwards."""
    from graphloc.eval import read_tum as evo_read_tum

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing")
    try:
        traj = evo_read_tum(path)
    except Exception as exc:  # evo raises its own FileInterfaceException / numpy errors
        raise ValueError(f"{path}: not a TUM trajectory ({exc})") from None
    times, poses = np.asarray(traj.timestamps, dtype=float), np.asarray(traj.poses_se3)
    if len(times) == 0 or not (np.isfinite(times).all() and np.isfinite(poses).all()):
        raise ValueError(f"{path}: empty or non-finite trajectory")
    back = np.flatnonzero(np.diff(times) <= 0)
    if len(back):
        raise ValueError(
            f"{path}: time goes backwards or repeats at pose {back[0] + 1} ({times[back[0] + 1]})"
        )
    return times, poses


def read_led_pixels(path, n_frames: int) -> np.ndarray:
    """LED pixel table `frame,time,led,u,v` (header line first) -> (n_frames,3,2), NaN where an LED
    was not seen. ValueError naming file:line on malformed rows, unknown frame/LED, non-finite
    pixels or a repeated (frame, led)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing")
    uv = np.full((int(n_frames), 3, 2), np.nan)
    columns = ["frame", "time", "led", "u", "v"]
    lines = text_lines(path)
    _, first = next(lines, (1, ""))
    if [h.strip() for h in first.split(",")] != columns:
        raise ValueError(f"{path}:1: header must be frame,time,led,u,v; got {shown(first)}")
    for line, text in lines:
        if not text.strip():
            continue
        try:
            row = csv_fields(text, columns)
            if len(row) != len(columns):
                raise ValueError(f"{len(row)} fields")
            f, _, k, u, v = int(row[0]), float(row[1]), int(row[2]), float(row[3]), float(row[4])
        except (ValueError, IndexError) as exc:
            raise ValueError(
                f"{path}:{line}: expected frame,time,led,u,v; got {shown(text)} ({exc})"
            ) from None
        if not 0 <= f < n_frames:
            raise ValueError(f"{path}:{line}: frame {f} outside [0, {n_frames})")
        if not 0 <= k < 3:
            raise ValueError(f"{path}:{line}: led {k} outside [0, 3)")
        if not (np.isfinite(u) and np.isfinite(v)):
            raise ValueError(f"{path}:{line}: non-finite pixel ({u}, {v})")
        if np.isfinite(uv[f, k]).all():
            raise ValueError(f"{path}:{line}: frame {f} led {k} given twice")
        uv[f, k] = (u, v)
    return uv
