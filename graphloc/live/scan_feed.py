"""`ScanFeed`: a live team's `scans` rows through KISS-ICP as they arrive (seed 004,
../shared/seeds/004_fa12d1d18dcbd0db.txt, Sec. II-B: each robot builds its own map from its
scan sequence), one `graphloc.mapping.odometry.ScanOdometry` -- KISS-ICP's own pipeline
object -- per (robot, scanner): each scan read when its row is released
(`graphloc.mapping.io.read_scan`, the loader's checks), registered onto the scans before it, and
the step from the scanner's previous scan made into the relative pose the loader makes of it
(`datasets.log_observations.scan_step`: the body frame through the extrinsics, `icp_sigmas`).
The steps are those of the whole-run loader (`log_observations.scan_odometry` feeds the same
object scan by scan), so a scan's step uses the scans before it only.

Memory stays bounded by one scan: a row names its file (a path in the run directory), the file
is read, registered and let go; what is kept is KISS-ICP's own voxel map (points within its
`max_range` of the scanner) and each scan's `ScanObservation` (time, robot, extrinsics, path).
A row whose file cannot be used (outside the run, unreadable, too few points, not in metres) is
a counted skip naming robot, table, row and field; non-finite points of a scan used are counted
(`scan_points_nonfinite`), a scan beyond the point budget thinned (`scan_thinned`, a note)."""

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
