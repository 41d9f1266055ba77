"""`ScanFeed`: a live team's `scans` rows through KISS-ICP as they arrive (seed 004 Sec. II-B),
one `mapping.odometry.ScanOdometry` per (robot, scanner), each step the relative pose the loader
makes of it (`log_observations.scan_step`); a scan that cannot be used is a counted skip."""

from __future__ import annotations

import gtsam

from graphloc.datasets.log_observations import scan_step
from graphloc.run import ScanObservation
from graphloc.textio import confined


class ScanFeed:
    """The scanners of a live team (`run`: its robots and their sensors; `root`: the run
    directory the rows' paths are in); `add(r, key, row)` -> (the scan's `ScanObservation`, the
    relative pose -- a `graphloc.run.Motion` -- it makes, None for a first scan), or None (a
    counted skip)."""

    def __init__(self, run, root, skips, notes):
        self.run, self.root = run, root
        self.skips, self.notes = skips, notes
        self.odometry: dict = {}  # (robot, sensor) -> (ScanOdometry, time of its last scan)
        self.scans: list = []  # ScanObservation of every scan used, in arrival order

    def add(self, r: int, key: tuple, row):
        """Robot r's released `scans` row (`key`: (robot, sensor), its handler's item)."""
        from graphloc.mapping.io import read_scan
        from graphloc.mapping.odometry import ScanOdometry

        robot = self.run.robots[r]
        where = f"robot {robot.name!r}, table 'scans', row {row.line}: field 'path'"
        try:
            path = self.root / confined(self.root, row.path, where)
            points, dropped = read_scan(path, self.notes)
        except ValueError as exc:
            reason = "path_outside_run" if where in str(exc) else "bad_scan"
            message = str(exc) if reason == "path_outside_run" else f"{where}: {exc}"
            self.skips.add(reason, message)
            return None
        except OSError as exc:
            self.skips.add("bad_scan", f"{where}: {row.path}: {exc.strerror or exc}")
            return None
        if dropped:
            self.skips.add(
                "scan_points_nonfinite", f"{where}: {dropped} non-finite points", dropped
            )
        T_bs, params = robot.sensors[row.sensor]
        scan = ScanObservation(row.time, r, gtsam.Pose3(T_bs), path)
        self.scans.append(scan)
        if key not in self.odometry:
            self.odometry[key] = (ScanOdometry(), None)
        odometry, last = self.odometry[key]
        step = odometry.add(points)
        self.odometry[key] = (odometry, row.time)
        if step is None:
            return scan, None
        return scan, scan_step(r, T_bs, params, last, row.time, step)
