"""UTIAS Multi-Robot Cooperative Localization and Mapping (MRCLAM) dataset loader
(Leung et al., IJRR 2011). Reads the directory layout of any MRCLAM_DatasetN:

    Barcodes.dat               subject #, barcode #
    Landmark_Groundtruth.dat   subject #, x, y, x std-dev, y std-dev
    RobotN_Odometry.dat        time, forward velocity v [m/s], angular velocity omega [rad/s]
    RobotN_Measurement.dat     time, barcode #, range [m], bearing [rad]
    RobotN_Groundtruth.dat     time, x, y, orientation   (optional)

Subjects 1..R are the robots (R = number of RobotN_Odometry.dat files), the others landmarks.
Every malformed line, NaN/inf, time going backwards, unknown barcode and self-observation is a
counted skip in the run's SkipReport (or a ValueError naming file and line with on_error="raise").

    run = MRCLAM("/data/MRCLAM_Dataset6", duration=60.0).load()    # graphloc.io.PlanarRun
    MRCLAM("/data/MRCLAM_Dataset6").to_log("out/ds6_log")           # graphloc log format
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from graphloc.io import PlanarRun, SkipReport, write_planar_run

_ROBOT_FILE = re.compile(r"^Robot(\d+)_Odometry\.dat$")


def is_mrclam_dir(path: str | Path) -> bool:
    p = Path(path)
    return (p / "Barcodes.dat").is_file() and any(_ROBOT_FILE.match(f.name) for f in p.glob("Robot*_Odometry.dat"))


def read_table(path: Path, n_cols: int, report: SkipReport, on_error: str = "skip", monotonic: bool = True,
               int_cols=()) -> np.ndarray:
    """Whitespace table with '#' comments -> (n, n_cols) float array. Malformed rows (wrong field
    count, unparsable or non-finite numbers, non-integer ids, time < previous time when
    `monotonic`) raise ValueError or are skipped and counted by reason."""
    rows = []
    last = -math.inf
    with open(path) as fh:
        for line_no, line in enumerate(fh, start=1):
            text = line.strip()
            if not text or text.startswith("#"):
                continue
            parts = text.split()
            reason = message = None
            if len(parts) != n_cols:
                reason, message = "field_count", f"expected {n_cols} fields, got {len(parts)}"
            else:
                try:
                    vals = [float(p) for p in parts]
                except ValueError:
                    reason, message = "parse", f"cannot parse {text!r} as numbers"
                else:
                    bad = next((i for i, v in enumerate(vals) if not math.isfinite(v)), None)
                    if bad is not None:
                        reason, message = "non_finite", f"field {bad + 1} ({parts[bad]}) is not finite"
                    elif any(vals[i] != int(vals[i]) for i in int_cols):
                        reason, message = "parse", f"id field is not an integer: {text!r}"
                    elif monotonic and vals[0] < last:
                        reason, message = "time_backwards", f"time {parts[0]} goes backwards (previous {last:.3f})"
            if reason is not None:
                full = f"{path}: line {line_no}: {message}"
                if on_error == "raise":
                    raise ValueError(full)
                report.add(reason, full)
                continue
            if monotonic:
                last = vals[0]
            rows.append(vals)
    return np.array(rows, dtype=float).reshape(-1, n_cols)


def interpolate_pose(gt: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Ground truth (G,4) time, x, y, theta linearly interpolated (heading unwrapped) at `times` -> (n,3)."""
    th = np.unwrap(gt[:, 3])
    out = np.stack([np.interp(times, gt[:, 0], gt[:, 1]), np.interp(times, gt[:, 0], gt[:, 2]),
                    np.interp(times, gt[:, 0], th)], axis=1)
    out[:, 2] = (out[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return out


class MRCLAM:
    """Loader of one MRCLAM dataset directory. `duration` (s after the common start) truncates."""

    def __init__(self, root: str | Path, duration: float | None = None, on_error: str = "skip"):
        self.root = Path(root)
        if not self.root.is_dir():
            raise FileNotFoundError(f"{self.root}: MRCLAM directory not found")
        if duration is not None and not (math.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be finite > 0, got {duration}")
        if on_error not in ("raise", "skip"):
            raise ValueError(f"on_error must be 'raise' or 'skip', got {on_error!r}")
        self.duration = duration
        self.on_error = on_error

    def robot_ids(self) -> list[int]:
        ids = sorted(int(m.group(1)) for f in self.root.iterdir() if (m := _ROBOT_FILE.match(f.name)))
        if not ids:
            raise ValueError(f"{self.root}: no RobotN_Odometry.dat files (not an MRCLAM directory?)")
        return ids

    def load(self) -> PlanarRun:
        report = SkipReport()
        ids = self.robot_ids()
        barcodes = read_table(self._file("Barcodes.dat"), 2, report, self.on_error, monotonic=False, int_cols=(0, 1))
        landmarks = read_table(self._file("Landmark_Groundtruth.dat"), 5, report, self.on_error, monotonic=False,
                               int_cols=(0,))
        barcode_to_subject = {}
        for subject, code in barcodes.astype(int):
            if code in barcode_to_subject:
                raise ValueError(f"{self.root / 'Barcodes.dat'}: barcode {code} assigned to two subjects")
            barcode_to_subject[code] = subject
        robot_index = {rid: i for i, rid in enumerate(ids)}

        odometry, groundtruth, meas = [], [], []
        for rid in ids:
            odo = read_table(self._file(f"Robot{rid}_Odometry.dat"), 3, report, self.on_error)
            if len(odo) < 2:
                raise ValueError(f"{self.root / f'Robot{rid}_Odometry.dat'}: fewer than 2 valid odometry rows")
            odometry.append(odo)
            gt_path = self.root / f"Robot{rid}_Groundtruth.dat"
            groundtruth.append(read_table(gt_path, 4, report, self.on_error) if gt_path.is_file() else None)
            mpath = self.root / f"Robot{rid}_Measurement.dat"
            meas.append(read_table(mpath, 4, report, self.on_error, int_cols=(1,)) if mpath.is_file() else np.zeros((0, 4)))

        start = max(od[0, 0] for od in odometry)
        end = min(od[-1, 0] for od in odometry)
        if self.duration is not None:
            end = min(end, start + self.duration)
        if end <= start:
            raise ValueError(f"{self.root}: robots' odometry does not overlap in time (start {start}, end {end})")

        obs = []
        for i, (rid, m) in enumerate(zip(ids, meas)):
            m = m[(m[:, 0] >= start) & (m[:, 0] <= end)]
            subject = np.array([barcode_to_subject.get(int(c), -1) for c in m[:, 1]], dtype=int)
            unknown = subject < 0
            if unknown.any():
                self._skip(report, "unknown_barcode", f"Robot{rid}_Measurement.dat",
                           f"{int(unknown.sum())} measurements of barcodes not in Barcodes.dat "
                           f"(e.g. {sorted(set(m[unknown, 1].astype(int).tolist()))[:5]})", int(unknown.sum()))
            own = subject == rid
            if own.any():
                self._skip(report, "self_observation", f"Robot{rid}_Measurement.dat",
                           f"{int(own.sum())} measurements of the robot's own barcode", int(own.sum()))
            nonpos = (m[:, 2] <= 0) & ~unknown & ~own
            if nonpos.any():
                self._skip(report, "non_positive_range", f"Robot{rid}_Measurement.dat",
                           f"{int(nonpos.sum())} measurements with range <= 0", int(nonpos.sum()))
            keep = ~unknown & ~own & ~nonpos
            target_robot = np.array([robot_index.get(s, -1) for s in subject[keep]], dtype=int)
            landmark = np.where(target_robot < 0, subject[keep], -1)
            obs.append(np.stack([m[keep, 0], np.full(keep.sum(), i), target_robot, landmark,
                                 m[keep, 2], m[keep, 3]], axis=1))
        o = np.concatenate(obs, axis=0)
        o = o[np.argsort(o[:, 0], kind="stable")]

        odometry = [od[od[:, 0] <= end] for od in odometry]
        init = np.full((len(ids), 3), np.nan)
        for i, gt in enumerate(groundtruth):
            if gt is not None and len(gt) >= 2:
                if not (gt[0, 0] <= start <= gt[-1, 0]):
                    raise ValueError(f"{self.root / f'Robot{ids[i]}_Groundtruth.dat'}: does not cover start time {start}")
                init[i] = interpolate_pose(gt, np.array([start]))[0]
                groundtruth[i] = gt[(gt[:, 0] >= start) & (gt[:, 0] <= end)]
        lm_is_robot = np.isin(landmarks[:, 0].astype(int), ids)
        if lm_is_robot.any():
            raise ValueError(f"{self.root / 'Landmark_Groundtruth.dat'}: subjects {landmarks[lm_is_robot, 0]} are robots")
        return PlanarRun(
            name=self.root.name, robots=tuple(f"robot{rid}" for rid in ids), start_time=float(start),
            initial_poses=init, odometry=tuple(odometry), groundtruth=tuple(groundtruth),
            obs_time=o[:, 0], obs_robot=o[:, 1].astype(int), obs_target_robot=o[:, 2].astype(int),
            obs_landmark=o[:, 3].astype(int), obs_range=o[:, 4], obs_bearing=o[:, 5],
            landmark_ids=landmarks[:, 0].astype(int), landmark_xy=landmarks[:, 1:3], landmark_sigma=landmarks[:, 3:5],
            skips=report, meta={"source": "MRCLAM", "directory": str(self.root)},
        )

    def to_log(self, out_dir: str | Path) -> Path:
        """Convert to the graphloc log format (docs/log_format.md)."""
        return write_planar_run(self.load(), out_dir)

    def _file(self, name: str) -> Path:
        path = self.root / name
        if not path.is_file():
            raise FileNotFoundError(f"{path}: required MRCLAM file missing")
        return path

    def _skip(self, report: SkipReport, reason: str, file: str, message: str, n: int) -> None:
        full = f"{self.root / file}: {message}"
        if self.on_error == "raise":
            raise ValueError(full)
        report.add(reason, full, n)
