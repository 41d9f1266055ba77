"""UTIAS MRCLAM dataset loader (Leung et al., IJRR 2011): a MRCLAM_DatasetN directory
(Barcodes.dat, Landmark_Groundtruth.dat, RobotN_Odometry / _Measurement / _Groundtruth.dat) ->
`graphloc.log_writer.PlanarRun`, every unused row a counted skip naming file and line
(docs/design_datasets.md, "MRCLAM")."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from graphloc.log_writer import PlanarRun
from graphloc.textio import SkipReport
from graphloc.textio import check_file, text_blocks

_ROBOT_FILE = re.compile(r"^Robot(\d+)_Odometry\.dat$")

# plausible ranges of every column, generous for lab robots (MRCLAM Dataset6: |v| <= 0.09 m/s,
# |omega| <= 0.6 rad/s, ranges 0.9-8.7 m, |bearing| <= 0.6 rad, positions within 6 m)
MAX_TIME = 1e11  # s (Unix time until the year 5138; relative times start near 0)
MAX_SPEED = 10.0  # m/s
MAX_TURN_RATE = 4 * math.pi  # rad/s
MAX_RANGE = 100.0  # m
MAX_COORDINATE = 1e4  # m, |x|, |y| of ground truth and landmarks
MAX_HEADING = 1e4  # rad (headings may be unwrapped)
MAX_SIGMA = 1e3  # m
MAX_ID = 1e6  # subject and barcode numbers
_TIME = ("time", -MAX_TIME, MAX_TIME)
LIMITS = {  # file kind -> (column name, low, high) per column
    "barcodes": (("subject", 1, MAX_ID), ("barcode", 0, MAX_ID)),
    "landmarks": (
        ("subject", 1, MAX_ID),
        ("x", -MAX_COORDINATE, MAX_COORDINATE),
        ("y", -MAX_COORDINATE, MAX_COORDINATE),
        ("x_sigma", 0.0, MAX_SIGMA),
        ("y_sigma", 0.0, MAX_SIGMA),
    ),
    "odometry": (_TIME, ("v", -MAX_SPEED, MAX_SPEED), ("omega", -MAX_TURN_RATE, MAX_TURN_RATE)),
    "measurement": (
        _TIME,
        ("barcode", 0, MAX_ID),
        ("range", -math.inf, MAX_RANGE),
        ("bearing", -2 * math.pi, 2 * math.pi),
    ),
    "groundtruth": (
        _TIME,
        ("x", -MAX_COORDINATE, MAX_COORDINATE),
        ("y", -MAX_COORDINATE, MAX_COORDINATE),
        ("theta", -MAX_HEADING, MAX_HEADING),
    ),
}
_INT_COLUMNS = {"barcodes": (0, 1), "landmarks": (0,), "measurement": (1,)}


def is_mrclam_dir(path: str | Path) -> bool:
    p = Path(path)
    barcodes = p / "Barcodes.dat"  # not a regular file: the reader says so, naming it
    return (barcodes.exists() or barcodes.is_symlink()) and any(
        _ROBOT_FILE.match(f.name) for f in p.glob("Robot*_Odometry.dat")
    )


def read_table(path: Path, kind: str, report: SkipReport, on_error: str = "skip") -> np.ndarray:
    """Whitespace table of one MRCLAM file `kind` (a key of LIMITS) -> (n, n_cols) floats; a row
    `_check_row` refuses raises or is a counted skip naming file, line and field. A block whose
    rows all pass is read at once (`_block_rows`), one with a bad row row by row."""
    limits = LIMITS[kind]
    n_cols, int_cols = len(limits), _INT_COLUMNS.get(kind, ())
    monotonic = limits[0][0] == "time"
    blocks = []
    last = -math.inf
    for first, texts in text_blocks(path):
        block = _block_rows(texts, limits, int_cols, last if monotonic else None)
        if block is None:
            data = [(first + k, t) for k, t in enumerate(map(str.strip, texts))]
            data = [(n, t) for n, t in data if t and not t.startswith("#")]
            block = []
            for line_no, text in data:
                reason, message = _check_row(
                    text, limits, int_cols, kind, last if monotonic else None
                )
                if reason is not None:
                    full = f"{path}: line {line_no}: {message}"
                    if on_error == "raise":
                        raise ValueError(full)
                    report.add(reason, full)
                    continue
                block.append([float(p) for p in text.split()])
                last = block[-1][0] if monotonic else last
        elif monotonic and len(block):
            last = float(block[-1, 0])
        blocks.append(np.array(block, dtype=float).reshape(-1, n_cols))
    return np.concatenate(blocks) if blocks else np.zeros((0, n_cols))


def _block_rows(texts: list, limits, int_cols, last: float | None) -> np.ndarray | None:
    """(n, n_cols) rows of a block's lines (blank and '#' lines left out) when every row passes
    `_check_row`'s checks (read by NumPy's C parser, `np.loadtxt`), else None."""
    if any(not t.lstrip().startswith("#") for t in texts if "#" in t):
        return None  # a '#' after other text: a bad row `_check_row` names
    if not any(t.strip() and not t.lstrip().startswith("#") for t in texts):
        return np.zeros((0, len(limits)))
    try:
        rows = np.loadtxt(texts, dtype=float, comments="#", ndmin=2)
    except ValueError:  # a row of another field count or an unparsable field
        return None
    if rows.shape[1] != len(limits):
        return None
    lo, hi = np.array([(a, b) for _, a, b in limits], dtype=float).T
    ok = np.isfinite(rows).all() and ((rows >= lo) & (rows <= hi)).all()
    ok = ok and all((rows[:, i] == np.trunc(rows[:, i])).all() for i in int_cols)
    ok = ok and all((rows[:, i] > 0).all() for i, (n, _, _) in enumerate(limits) if n == "range")
    if ok and last is not None and len(rows):
        ok = rows[0, 0] >= last and (np.diff(rows[:, 0]) >= 0).all()
    return rows if ok else None


def _check_row(text: str, limits, int_cols, kind: str, last: float | None):
    """(reason, message) of the first problem of one row, or (None, None)."""
    parts = text.split()
    if len(parts) != len(limits):
        return "field_count", f"expected {len(limits)} fields, got {len(parts)}"
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        shown = text if len(text) <= 80 else text[:77] + "..."
        return "parse", f"cannot parse {shown!r} as numbers"
    for i, (v, (name, lo, hi)) in enumerate(zip(vals, limits)):
        field = f"field {i + 1} ({name})"
        if not math.isfinite(v):
            return "non_finite", f"{field} = {parts[i]} is not finite"
        if i in int_cols and v != int(v):
            return "parse", f"{field} = {parts[i]} is not an integer"
        if name == "range" and v <= 0:
            return "non_positive_range", f"{field} = {parts[i]} is not > 0"
        if not lo <= v <= hi:
            return "implausible", f"{field} = {parts[i]} is outside the plausible [{lo:g}, {hi:g}]"
    if last is not None and vals[0] < last:
        return "time_backwards", f"time {parts[0]} goes backwards (previous {last:.3f})"
    return None, None


def interpolate_pose(gt: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Ground truth (G,4) time, x, y, theta linearly interpolated (heading unwrapped) at `times`
    -> (n,3)."""
    th = np.unwrap(gt[:, 3])
    out = np.stack([np.interp(times, gt[:, 0], v) for v in (gt[:, 1], gt[:, 2], th)], axis=1)
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

    def load(self) -> PlanarRun:
        report = SkipReport()
        ids = sorted(
            int(m.group(1)) for f in self.root.iterdir() if (m := _ROBOT_FILE.match(f.name))
        )
        if not ids:
            raise ValueError(
                f"{self.root}: no RobotN_Odometry.dat files (not an MRCLAM directory?)"
            )
        barcodes = read_table(self._file("Barcodes.dat"), "barcodes", report, "raise")
        lm_path = self._file("Landmark_Groundtruth.dat")
        landmarks = read_table(lm_path, "landmarks", report, "raise")
        if len(landmarks) == 0:
            raise ValueError(
                f"{lm_path}: no landmark rows (only comments or blank lines): an "
                f"MRCLAM run needs its landmark map"
            )
        subjects, n_rows = np.unique(landmarks[:, 0].astype(int), return_counts=True)
        if (n_rows > 1).any():
            twice = subjects[n_rows > 1].tolist()
            raise ValueError(f"{lm_path}: landmark subject(s) {twice} listed more than once")
        barcode_to_subject = {}
        for subject, code in barcodes.astype(int):
            if code in barcode_to_subject:
                raise ValueError(
                    f"{self.root / 'Barcodes.dat'}: barcode {code} assigned to two subjects"
                )
            barcode_to_subject[code] = subject
        robot_index = {rid: i for i, rid in enumerate(ids)}

        odometry, groundtruth, meas = [], [], []
        for rid in ids:
            odo = read_table(
                self._file(f"Robot{rid}_Odometry.dat"), "odometry", report, self.on_error
            )
            if len(odo) < 2:
                raise ValueError(
                    f"{self.root / f'Robot{rid}_Odometry.dat'}: fewer than 2 valid odometry rows"
                )
            odometry.append(odo)
            gt_path = self.root / f"Robot{rid}_Groundtruth.dat"
            has_gt = check_file(gt_path, required=False, what="MRCLAM file")
            groundtruth.append(
                read_table(gt_path, "groundtruth", report, self.on_error) if has_gt else None
            )
            meas.append(
                read_table(
                    self._file(f"Robot{rid}_Measurement.dat"), "measurement", report, self.on_error
                )
            )

        first_row = [od[0, 0] for od in odometry]
        last_row = [od[-1, 0] for od in odometry]
        start, end = max(first_row), min(last_row)
        window = {
            "start": float(start),
            "end": float(end),
            "start_set_by": f"Robot{ids[int(np.argmax(first_row))]}_Odometry.dat "
            f"(latest first row)",
            "end_set_by": f"Robot{ids[int(np.argmin(last_row))]}_Odometry.dat (earliest last row)",
        }
        odo_end = end
        if self.duration is not None and start + self.duration < end:
            end = start + self.duration
            window.update(end=float(end), end_set_by=f"duration {self.duration} s")
        if end <= start:
            raise ValueError(
                f"{self.root}: robots' odometry does not overlap in time (start "
                f"{start} from {window['start_set_by']}, end {end} from "
                f"{window['end_set_by']})"
            )
        for rid, od, m in zip(ids, odometry, meas):
            self._count_outside(
                report, f"Robot{rid}_Measurement.dat", "", m[:, 0], start, end, odo_end
            )
            self._count_outside(
                report, f"Robot{rid}_Odometry.dat", "odometry_", od[:, 0], -math.inf, end, odo_end
            )

        obs = []
        for i, (rid, m) in enumerate(zip(ids, meas)):
            m = m[(m[:, 0] >= start) & (m[:, 0] <= end)]
            subject = np.array([barcode_to_subject.get(int(c), -1) for c in m[:, 1]], dtype=int)
            unknown = subject < 0
            if unknown.any():
                self._skip(
                    report,
                    "unknown_barcode",
                    f"Robot{rid}_Measurement.dat",
                    f"{int(unknown.sum())} measurements of barcodes not in Barcodes.dat "
                    f"(e.g. {sorted(set(m[unknown, 1].astype(int).tolist()))[:5]})",
                    int(unknown.sum()),
                )
            own = subject == rid
            if own.any():
                self._skip(
                    report,
                    "self_observation",
                    f"Robot{rid}_Measurement.dat",
                    f"{int(own.sum())} measurements of the robot's own barcode",
                    int(own.sum()),
                )
            keep = ~unknown & ~own
            target_robot = np.array([robot_index.get(s, -1) for s in subject[keep]], dtype=int)
            landmark = np.where(target_robot < 0, subject[keep], -1)
            # time, observer, target robot, landmark, range, bearing
            columns = [m[keep, 0], np.full(keep.sum(), i), target_robot, landmark, m[keep, 2:4]]
            obs.append(np.column_stack(columns))
        o = np.concatenate(obs, axis=0)
        o = o[np.argsort(o[:, 0], kind="stable")]

        odometry = [od[od[:, 0] <= end] for od in odometry]
        init = np.full((len(ids), 3), np.nan)
        for i, gt in enumerate(groundtruth):
            if gt is not None and len(gt) >= 2:
                if not (gt[0, 0] <= start <= gt[-1, 0]):
                    raise ValueError(
                        f"{self.root / f'Robot{ids[i]}_Groundtruth.dat'}: "
                        f"does not cover start time {start}"
                    )
                init[i] = interpolate_pose(gt, np.array([start]))[0]
                inside = (gt[:, 0] >= start) & (gt[:, 0] <= end)
                if not inside.all():
                    n_out = int((~inside).sum())
                    self._skip(
                        report,
                        "groundtruth_outside_window",
                        f"Robot{ids[i]}_Groundtruth.dat",
                        f"{n_out} ground-truth rows "
                        f"outside the run window [{start:.3f}, {end:.3f}]",
                        n_out,
                        strict=False,
                    )
                groundtruth[i] = gt[inside]
        lm_is_robot = np.isin(landmarks[:, 0].astype(int), ids)
        if lm_is_robot.any():
            raise ValueError(
                f"{self.root / 'Landmark_Groundtruth.dat'}: "
                f"subjects {landmarks[lm_is_robot, 0]} are robots"
            )
        return PlanarRun(
            name=self.root.name,
            robots=tuple(f"robot{rid}" for rid in ids),
            start_time=float(start),
            initial_poses=init,
            odometry=tuple(odometry),
            groundtruth=tuple(groundtruth),
            obs_time=o[:, 0],
            obs_robot=o[:, 1].astype(int),
            obs_target_robot=o[:, 2].astype(int),
            obs_landmark=o[:, 3].astype(int),
            obs_range=o[:, 4],
            obs_bearing=o[:, 5],
            landmark_ids=landmarks[:, 0].astype(int),
            landmark_xy=landmarks[:, 1:3],
            landmark_sigma=landmarks[:, 3:5],
            skips=report,
            meta={"source": "MRCLAM", "directory": str(self.root), "window": window},
        )

    def _count_outside(
        self,
        report: SkipReport,
        file: str,
        prefix: str,
        t: np.ndarray,
        start: float,
        end: float,
        odo_end: float,
    ) -> None:
        """Count rows of `file` with times `t` outside [start, end] as prefix + before_start,
        after_end (past the earliest end of any robot's odometry) or after_duration (cut by
        `duration`)."""
        for reason, mask, where in (
            ("before_start", t < start, f"before the common start {start:.3f}"),
            ("after_duration", (t > end) & (t <= odo_end), f"after start + duration = {end:.3f}"),
            ("after_end", t > odo_end, f"after the end of the shortest odometry {odo_end:.3f}"),
        ):
            n = int(mask.sum())
            if n:
                self._skip(
                    report,
                    prefix + reason,
                    file,
                    f"{n} rows {where} (first at time {t[mask][0]:.3f})",
                    n,
                    strict=False,
                )

    def _file(self, name: str) -> Path:
        path = self.root / name
        check_file(path, what="MRCLAM file")
        return path

    def _skip(
        self, report: SkipReport, reason: str, file: str, message: str, n: int, strict: bool = True
    ) -> None:
        """Count n skipped rows; with on_error="raise" a ValueError instead, unless `strict` is
        False (rows outside the run window are a property of the run, not an input error)."""
        full = f"{self.root / file}: {message}"
        if strict and self.on_error == "raise":
            raise ValueError(full)
        report.add(reason, full, n)
