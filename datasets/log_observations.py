"""Log tables that become observations in batches: `markers` rows -> P3P candidate sets (seed 000
Sec. III-B, seed 004 Sec. II-C: three markers; seed 001 Sec. IV-C: four identical markers),
`candidates` rows -> candidate sets, a robot's `scans` -> KISS-ICP odometry steps."""

from __future__ import annotations

from collections import Counter

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.candidates import CandidateSet
from graphloc.datasets.camera_tables import camera_sensor, positive_param
from graphloc.textio import Sink
from graphloc.table_reader import iter_table_chunks
from graphloc.textio import cut
from graphloc.run import CandidateObservation, MarkerPixels, Motion, ScanObservation
from graphloc.vision.marker_poses import p3p_candidate_sets


MARKER_COLUMNS = ("time", "robot", "sensor", "target", "marker", "u", "v", "line")


def marker_columns(manifest, robots: tuple, index: dict, on_error: str, report, landmark_ids):
    """Every robot's `markers` rows that pass the row checks
    (`graphloc.table_reader.iter_table_chunks`), as compact columns (MARKER_COLUMNS: time,
    observer index, sensor as an index into the observer's sensor names, target robot index,
    marker, u, v, line), read a chunk at a time so that only these arrays stay in memory; a
    row whose target is not a robot is a counted skip `unknown_target` (markers are on robots
    with a 'markers' layout)."""
    sink = Sink(on_error, report)
    parts = []
    for ri, r in enumerate(manifest.robots):
        if "markers" not in r.tables:
            continue
        path = manifest.root / r.tables["markers"]
        names = {name: k for k, name in enumerate(robots[ri].sensors)}
        for chunk in iter_table_chunks(manifest, r, "markers", on_error, report, landmark_ids):
            target = np.array([index.get(t, -1) for t in chunk["target"]], dtype=np.int32)
            for k in np.flatnonzero(target < 0):
                message = ""
                if sink.wants_message():
                    message = (
                        f"{path}: line {chunk['line'][k]}: field 'target': "
                        f"{chunk['target'][k]!r} is not a robot (markers are on robots with a "
                        f"'markers' layout)"
                    )
                sink.bad("unknown_target", message)
            keep = target >= 0
            sensor = np.array([names[s] for s in chunk["sensor"]], dtype=np.int32)
            robot = np.full(len(target), ri, dtype=np.int32)
            marker = chunk["marker"].astype(np.int32)
            time, u, v, line = (chunk[k] for k in ("time", "u", "v", "line"))
            parts.append(tuple(c[keep] for c in (time, robot, sensor, target, marker, u, v, line)))
    if not parts:
        return None
    return dict(zip(MARKER_COLUMNS, (np.concatenate(c) for c in zip(*parts))))


def marker_observations(
    columns: dict | None, robots: tuple, manifest, d: dict, sink: Sink
) -> tuple[list, int]:
    """Marker pixels (`marker_columns`) grouped by image (time, observer, sensor, target), an
    image with a marker outside the layout, one seen twice (markers not identical) or fewer than
    three a counted skip of its rows, then P3P in one batched solve. Returns the candidate sets
    and the number of rows that became non-empty sets."""
    if columns is None or not len(columns["time"]):
        return [], 0
    c = columns
    order = np.lexsort((c["line"], c["target"], c["sensor"], c["robot"], c["time"]))
    c = {k: v[order] for k, v in c.items()}
    keys = (c["time"], c["robot"], c["sensor"], c["target"])
    change = np.zeros(len(c["time"]), bool)
    change[0] = True
    for key in keys:
        change[1:] |= key[1:] != key[:-1]
    starts = np.flatnonzero(change)
    sizes = np.diff(np.r_[starts, len(change)])
    group = np.repeat(np.arange(len(starts)), sizes)
    g_robot, g_target = c["robot"][starts], c["target"][starts]
    layout = np.array([-1 if r.markers is None else len(r.markers) for r in robots])
    identical = np.array([bool(r.identical_markers) for r in robots])
    first_line = np.minimum.reduceat(c["line"], starts)
    last_line = np.maximum.reduceat(c["line"], starts)

    def where(k: int) -> str:
        table = manifest.root / manifest.robots[g_robot[k]].tables["markers"]
        return f"{table}: lines {first_line[k]}-{last_line[k]}"

    no_layout = np.flatnonzero(layout[g_target] < 0)
    if len(no_layout):
        k = int(no_layout[0])
        raise ValueError(
            f"{where(k)}: field 'target': robot {robots[g_target[k]].name!r} has no 'markers' "
            f"layout in the manifest"
        )
    marker = c["marker"]
    outside = (marker < 0) | (marker >= layout[c["target"]])
    unknown = np.logical_or.reduceat(outside, starts)
    by_marker = np.lexsort((marker, group))
    same = (group[by_marker][1:] == group[by_marker][:-1]) & (
        marker[by_marker][1:] == marker[by_marker][:-1]
    )
    repeated = np.zeros(len(starts), bool)
    repeated[group[by_marker][1:][same]] = True
    repeated &= ~identical[g_target] & ~unknown
    few = (sizes < 3) & ~unknown & ~repeated
    for reason, mask, text in (
        ("unknown_marker", unknown, "field 'marker': {marks} outside the layout of {n} markers"),
        ("duplicate_marker", repeated, "field 'marker': a marker appears twice in one image"),
        ("too_few_markers", few, "{size} markers seen, P3P needs 3"),
    ):
        for k in np.flatnonzero(mask):
            message = ""
            if sink.wants_message():
                marks = marker[starts[k] : starts[k] + min(sizes[k], 20)].tolist()
                message = f"{where(k)}: " + text.format(
                    marks=cut(str(marks)), n=layout[g_target[k]], size=sizes[k]
                )
            sink.bad(reason, message, int(sizes[k]))
    by_setup: dict = {}
    for k in np.flatnonzero(~(unknown | repeated | few)):
        rows = slice(starts[k], starts[k] + sizes[k])
        key = (int(g_robot[k]), int(c["sensor"][starts[k]]), int(g_target[k]))
        uv = np.column_stack([c["u"][rows], c["v"][rows]])
        by_setup.setdefault(key, []).append(
            (float(c["time"][starts[k]]), c["marker"][rows].astype(int), uv, where(k))
        )
    out, used = [], 0
    for (ri, s, ti), frames in by_setup.items():
        sensor = list(robots[ri].sensors)[s]  # marker_columns' sensor index
        E, params, camera, where_cam = camera_sensor(robots, ri, sensor, manifest)
        sigma = positive_param(params, "pixel_sigma", d["pixel_sigma"], where_cam)
        target = robots[ti]
        sets = p3p_candidate_sets(
            camera,
            [f[2] for f in frames],
            [f[1] for f in frames],
            target.markers,
            [f[0] for f in frames],
            sigma,
            identical=target.identical_markers,
            observer=robots[ri].name,
            observed=target.name,
        )
        for (time, marks, uv, lines), cs in zip(frames, sets):
            if cs is None or (len(cs) == 0 and not cs.meta.get("inconsistent")):
                message = f"{lines}: fields 'u, v': no pose fits the marker pixels"
                sink.bad("no_p3p_solution", message, len(marks))
                continue
            # an inconsistent set (no pose passes the pixel chi-square) stays, empty: the team
            # graph counts it in its stream and never decides it
            pixels = None if target.identical_markers else MarkerPixels(marks, uv, camera, sigma)
            out.append(CandidateObservation(time, ri, ti, E, cs, pixels))
            if len(cs):  # an inconsistent set's rows are counted by the graph, as skipped
                used += len(marks)
    return out, used


SCAN_SIGMAS = (0.002, 0.01)  # [rad, m] per KISS-ICP step where the scanner's params give none


def scan_odometry(groups: dict, robots: tuple, manifest, report, notes=None) -> tuple[list, list]:
    """Each robot's scans (per scanner) -> KISS-ICP odometry, one body-frame step per pair of
    consecutive scans (`scan_step`); and the scans themselves (`ScanObservation`) for the team
    graph's inter-robot registration."""
    if not groups:
        return [], []
    # Open3D and KISS-ICP load only for runs that have scans
    from graphloc.mapping.io import check_scan_units, read_scan
    from graphloc.mapping.odometry import ScanOdometry

    out, observed, sequences = [], [], {}
    for (ri, sensor), rows in groups.items():
        T_bs, params = robots[ri].sensors[sensor]
        E = gtsam.Pose3(T_bs)
        observed += [ScanObservation(r.time, ri, E, manifest.root / r.path) for r in rows]
        scans = []
        for row in rows:
            table = manifest.root / manifest.robots[ri].tables["scans"]
            try:
                points, dropped = read_scan(manifest.root / row.path, notes)
            except (OSError, ValueError) as exc:
                raise ValueError(f"{table}: line {row.line}: field 'path': {exc}") from None
            scans.append(points)
            if dropped:
                where = f"{table}: line {row.line}: field 'path'"
                report.add(
                    "scan_points_nonfinite", f"{where}: {dropped} non-finite points", dropped
                )
        sequences[(ri, sensor)] = (scans, [manifest.root / r.path for r in rows])
    if len({ri for ri, _ in groups}) > 1:  # registered with each other: one unit, checked first
        check_scan_units({f"{robots[ri].name}/{s}": seq for (ri, s), seq in sequences.items()})
    for (ri, sensor), rows in groups.items():
        T_bs, params = robots[ri].sensors[sensor]
        odometry = (
            ScanOdometry()
        )  # scan by scan, as the live team feeds it (`live.event_rows.ScanFeed`)
        steps = [odometry.add(points) for points in sequences[(ri, sensor)][0]]
        for a, b, step in zip(rows[:-1], rows[1:], steps[1:]):
            out.append(scan_step(ri, T_bs, params, a.time, b.time, step))
    return out, observed


def scan_step(ri: int, T_bs, params: dict, t0: float, t1: float, step) -> Motion:
    """One KISS-ICP step of robot ri's scanner from t0 to t1 as a relative pose of the body,
    covariance from the scanner's `icp_sigmas` [rot rad, trans m] (default SCAN_SIGMAS)."""
    E = gtsam.Pose3(T_bs)
    sig = params.get("icp_sigmas", SCAN_SIGMAS)
    cov = np.diag([float(sig[0]) ** 2] * 3 + [float(sig[1]) ** 2] * 3)
    A = E.AdjointMap()
    rel = E.compose(gtsam.Pose3(step)).compose(E.inverse())
    return Motion(ri, t0, t1, rel, A @ cov @ A.T)


def candidate_observations(groups: dict, robots: tuple, d: dict, manifest, sink: Sink) -> list:
    """`candidates` rows grouped by (time, observer, sensor, target) -> candidate sets as
    logged, with the sensor's `candidate_sigmas` (rot rad, trans m); a set listing a candidate
    `k` twice is a counted skip `duplicate_candidate` of its every row."""
    out = []
    for (time, ri, sensor, ti), rows in groups.items():
        ks = [r.k for r in rows]
        if len(set(ks)) != len(ks):
            table = manifest.root / manifest.robots[ri].tables["candidates"]
            lines = sorted(r.line for r in rows)
            repeated = sorted(k for k, n in Counter(ks).items() if n > 1)[:10]
            sink.bad(
                "duplicate_candidate",
                f"{table}: lines {lines[0]}-{lines[-1]}: field 'k': candidate(s) {repeated} "
                f"listed twice in one set",
                len(rows),
            )
            continue
        T_bs, params = robots[ri].sensors[sensor]
        sig = params.get("candidate_sigmas", d["candidate_sigmas"])
        rows = sorted(rows, key=lambda r: r.k)
        q = np.array([[r.qx, r.qy, r.qz, r.qw] for r in rows])
        R = Rotation.from_quat(q / np.linalg.norm(q, axis=1, keepdims=True)).as_matrix()
        t = np.array([[r.tx, r.ty, r.tz] for r in rows])
        cov = np.broadcast_to(
            np.diag([sig[0] ** 2] * 3 + [sig[1] ** 2] * 3), (len(rows), 6, 6)
        ).copy()
        cs = CandidateSet(
            R,
            t,
            np.array([r.score for r in rows]),
            time=time,
            observer=robots[ri].name,
            observed=robots[ti].name,
            source="candidates-table",
            covariance=cov,
        )
        out.append(CandidateObservation(time, ri, ti, gtsam.Pose3(T_bs), cs))
    return out
