"""Reader of a graphloc log directory (docs/log_format.md, versions 1 and 2) into the one run
type, `graphloc.run.TeamRun`: every row of every table used, counted as a skip with its reason,
or rejected with file, line and field. Front-end work that needs no estimate happens here,
once: marker pixels become P3P candidate sets and a robot's scans KISS-ICP odometry steps
(`graphloc.datasets.log_observations`), feature and ellipse rows camera observations
(`graphloc.datasets.camera_tables`).
"""

from __future__ import annotations

from pathlib import Path

import gtsam
import numpy as np

from graphloc.factors.surface import SurfacePlane
from graphloc.io import (
    LANDMARK_PREFIX,
    MANIFEST,
    Bearing3D,
    GroundTruth2D,
    Odometry2D,
    PoseCandidate,
    Range,
    RangeBearing2D,
    RelativePose2D,
    RelativePose3D,
    ScanRef,
    TABLES,
    SkipReport,
    Sink,
    is_tum,
    iter_records,
    read_landmarks,
    read_manifest,
)
from graphloc.run import (
    NOISE_DEFAULTS,
    Motion,
    PointMeasurement,
    TeamRobot,
    TeamRun,
    planar_covariance,
    pose_from_planar,
    pose_from_xyz_quat,
)
from graphloc.datasets.camera_tables import (
    ellipse_observations,
    feature_observations,
    positive_param,
    single_tracks,
)
from graphloc.datasets.log_observations import (
    candidate_observations,
    marker_columns,
    marker_observations,
    scan_odometry,
)
from graphloc.textio import check_file, shown, text_lines
from graphloc.records import MAX_COORDINATE, MAX_TIME, EllipseObservation, FeaturePixel

# tables the graph uses (every table of docs/log_format.md)
GRAPH_TABLES = (
    "scans",
    "odometry",
    "relative_pose",
    "relative_pose3",
    "range",
    "bearing",
    "range_bearing",
    "markers",
    "features",
    "ellipses",
    "candidates",
    "groundtruth",
)


def read_tum_poses(path: Path) -> tuple[np.ndarray, list]:
    """TUM file (timestamp tx ty tz qx qy qz qw; '#' comments) -> times, Pose3 list. ValueError
    naming file and line on a malformed row."""
    times, poses = [], []
    check_file(path, what="ground-truth TUM file")
    for n, line in text_lines(path):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        parts = text.split()
        try:
            vals = np.array([float(p) for p in parts])
        except ValueError:
            raise ValueError(f"{path}: line {n}: cannot parse {shown(text)} as 8 numbers") from None
        if vals.size != 8 or not np.isfinite(vals).all():
            raise ValueError(
                f"{path}: line {n}: expected 8 finite numbers (timestamp tx ty tz qx qy qz qw)"
            )
        if abs(vals[0]) > MAX_TIME or np.abs(vals[1:4]).max() > MAX_COORDINATE:
            raise ValueError(
                f"{path}: line {n}: field 'timestamp' or 'tx, ty, tz' outside the plausible "
                f"+-{MAX_TIME:g} s / +-{MAX_COORDINATE:g} m"
            )
        if not 0.5 < np.linalg.norm(vals[4:]) < 2.0:
            raise ValueError(f"{path}: line {n}: field 'q': quaternion is not unit")
        if times and vals[0] < times[-1]:
            raise ValueError(f"{path}: line {n}: field 'timestamp': {vals[0]} goes backwards")
        times.append(vals[0])
        poses.append(pose_from_xyz_quat(vals[1:]))
    return np.array(times), poses


def _robot(r, where: str) -> TeamRobot:
    init = None
    if r.initial_pose is not None:
        init = (
            pose_from_planar(*r.initial_pose)
            if len(r.initial_pose) == 3
            else pose_from_xyz_quat(r.initial_pose)
        )
    surface = (
        None
        if r.surface is None
        else SurfacePlane(np.array(r.surface["point"]), np.array(r.surface["normal"]))
    )
    markers = None if r.markers is None else np.array(r.markers, dtype=float)
    sensors = {s.name: (s.body_T_sensor, dict(s.params)) for s in r.sensors}
    return TeamRobot(
        r.name,
        r.kind,
        bool(r.planar),
        bool(r.static),
        init,
        r.initial_sigma,
        surface,
        markers,
        bool(r.identical_markers),
        sensors,
        surface_sigma=None if r.surface is None else r.surface.get("distance_sigma"),
        attitude_sigma=None if r.surface is None else r.surface.get("attitude_sigma"),
        body_axis=tuple((r.surface or {}).get("body_axis", (0.0, 0.0, 1.0))),
        base_radius=r.base_radius,
    )


def read_team_run(
    root: str | Path,
    on_error: str = "skip",
    defaults: dict | None = None,
    overrides: dict | None = None,
) -> TeamRun:
    """A graphloc log directory -> TeamRun. Every row of every table is used, counted as a skip
    with its reason (`on_error="skip"`), or raises naming file, line and field. `defaults`:
    sensor noise used where a sensor's params give none (bearing_sigma [rad], range_sigma [m],
    range_sigma_per_m, pixel_sigma [px], candidate_sigmas (rot, trans)); `overrides`: the same
    names, replacing what every sensor's params say (a config file or CLI flags)."""
    d = {**NOISE_DEFAULTS, **(defaults or {})}
    forced = dict(overrides or {})
    manifest = read_manifest(root)
    mpath = manifest.root / MANIFEST
    for r in manifest.robots:
        for s in r.sensors:
            s.params.update(forced)
    report = SkipReport()
    notes = SkipReport()  # read and used, but said: scans thinned, a bag's stamps re-sorted
    sink = Sink(on_error, report)
    robots = tuple(_robot(r, f"{mpath}: robots[{i}]") for i, r in enumerate(manifest.robots))
    index = {r.name: i for i, r in enumerate(robots)}
    ids, xyz, sig = read_landmarks(manifest)
    velocity = {r.name: [] for r in robots}
    motions, points, gt = [], [], {r.name: None for r in robots}
    gt2d = {r.name: [] for r in robots}
    cand_rows: dict = {}
    scan_rows: dict = {}
    feature_rows: list = []
    ellipse_rows: list = []
    used = {t: 0 for t in GRAPH_TABLES}
    for r in manifest.robots:  # 3D ground truth in TUM files
        path = r.tables.get("groundtruth")
        if path and is_tum(path):
            gt[r.name] = read_tum_poses(manifest.root / path)
            used["groundtruth"] += len(gt[r.name][0])
    # marker rows are read as columns (`marker_columns`: a million rows in seconds); every
    # other table as records merged in time order
    streamed = tuple(t for t in GRAPH_TABLES if t != "markers")
    for rec in iter_records(root, tables=streamed, on_error=on_error, report=report):
        where = (
            f"{manifest.root / manifest.robot(rec.robot).tables[_table_of(rec)]}: line {rec.line}"
        )
        ri = index[rec.robot]
        robot = robots[ri]
        if isinstance(rec, GroundTruth2D):
            gt2d[rec.robot].append((rec.time, rec.x, rec.y, rec.theta))
            used["groundtruth"] += 1
            continue
        T_bs, params = robot.sensors[rec.sensor]
        E = gtsam.Pose3(T_bs)
        if isinstance(rec, Odometry2D):
            velocity[rec.robot].append((rec.time, rec.v, rec.omega))
        elif isinstance(rec, RelativePose2D):
            sig3 = np.array([rec.sigma_x, rec.sigma_y, rec.sigma_theta])
            if not (sig3 > 0).all() or not rec.time > rec.time0:
                sink.bad(
                    "bad_relative_pose", f"{where}: fields 'sigma_*' must be > 0 and time0 < time"
                )
                continue
            motions.append(
                Motion(
                    ri,
                    rec.time0,
                    rec.time,
                    pose_from_planar(rec.dx, rec.dy, rec.dtheta),
                    planar_covariance(np.diag(sig3**2)),
                )
            )
        elif isinstance(rec, RelativePose3D):
            sig6 = np.array(
                [rec.sigma_rx, rec.sigma_ry, rec.sigma_rz, rec.sigma_tx, rec.sigma_ty, rec.sigma_tz]
            )
            q = np.array([rec.qx, rec.qy, rec.qz, rec.qw])
            if (
                not (sig6 > 0).all()
                or not rec.time > rec.time0
                or not 0.5 < np.linalg.norm(q) < 2.0
            ):
                sink.bad(
                    "bad_relative_pose",
                    f"{where}: fields 'sigma_*' must be > 0, time0 < time and the quaternion unit",
                )
                continue
            motions.append(
                Motion(
                    ri,
                    rec.time0,
                    rec.time,
                    pose_from_xyz_quat([rec.tx, rec.ty, rec.tz, *q]),
                    np.diag(sig6**2),
                )
            )
        elif isinstance(rec, (Bearing3D, Range, RangeBearing2D)):
            target = rec.target
            if target == rec.robot:
                sink.bad(
                    "self_observation",
                    f"{where}: field 'target': robot {rec.robot} observes itself",
                )
                continue
            t_idx = index.get(target, -1)
            lid = -1 if t_idx >= 0 else int(target[len(LANDMARK_PREFIX) :])
            bs = positive_param(params, "bearing_sigma", d["bearing_sigma"], where)
            rs0 = positive_param(params, "range_sigma", d["range_sigma"], where)
            rs1 = positive_param(params, "range_sigma_per_m", d["range_sigma_per_m"], where)
            if isinstance(rec, Bearing3D):
                v = np.array([rec.x, rec.y, rec.z])
                n = np.linalg.norm(v)
                if not 0.5 < n < 2.0:
                    sink.bad(
                        "not_unit",
                        f"{where}: fields 'x, y, z': |direction| = {n:.3g} is not a unit vector",
                    )
                    continue
                points.append(
                    PointMeasurement(
                        "bearing", rec.time, ri, E, t_idx, lid, v / n, np.nan, bs, np.nan
                    )
                )
            else:
                if not rec.range > 0:
                    sink.bad("non_positive_range", f"{where}: field 'range': {rec.range} <= 0")
                    continue
                rsig = float(np.hypot(rs0, rs1 * rec.range))
                if isinstance(rec, Range):
                    points.append(
                        PointMeasurement(
                            "range",
                            rec.time,
                            ri,
                            E,
                            t_idx,
                            lid,
                            np.full(3, np.nan),
                            rec.range,
                            np.nan,
                            rsig,
                        )
                    )
                else:
                    v = np.array([np.cos(rec.bearing), np.sin(rec.bearing), 0.0])
                    points.append(
                        PointMeasurement(
                            "range_bearing", rec.time, ri, E, t_idx, lid, v, rec.range, bs, rsig
                        )
                    )
        elif isinstance(rec, ScanRef):
            scan_rows.setdefault((ri, rec.sensor), []).append(rec)
        elif isinstance(rec, FeaturePixel):
            feature_rows.append((ri, rec))
        elif isinstance(rec, EllipseObservation):
            if rec.target not in index or rec.target == rec.robot:
                sink.bad(
                    "unknown_target",
                    f"{where}: field 'target': {rec.target!r} is not another robot",
                )
                continue
            ellipse_rows.append((ri, index[rec.target], rec, where))
        elif isinstance(rec, PoseCandidate):
            if rec.target not in index:
                sink.bad(
                    "unknown_target", f"{where}: field 'target': {rec.target!r} is not a robot"
                )
                continue
            norm = float(np.linalg.norm([rec.qw, rec.qx, rec.qy, rec.qz]))
            if not 0.5 < norm < 2.0:
                sink.bad(
                    "not_unit",
                    f"{where}: fields 'qw, qx, qy, qz': |q| = {norm:.3g} is not a unit quaternion",
                )
                continue
            cand_rows.setdefault((rec.time, ri, rec.sensor, index[rec.target]), []).append(rec)
            continue  # counted in `used` when its set is formed (candidate_observations)
        used[_table_of(rec)] += 1
    scan_motions, scans = scan_odometry(scan_rows, robots, manifest, report, notes)
    motions += scan_motions
    landmark_ids = None if manifest.landmarks_file is None else set(ids.tolist())
    markers = marker_columns(manifest, robots, index, on_error, report, landmark_ids)
    observations = marker_observations(markers, robots, manifest, d, sink, used)
    observations += candidate_observations(cand_rows, robots, d, manifest, sink, used)
    observations += ellipse_observations(ellipse_rows, robots, manifest, sink)
    feature_rows = single_tracks(feature_rows, manifest, sink, used)
    features = feature_observations(feature_rows, robots, manifest, d)
    observations.sort(key=lambda o: (o.time, o.robot))
    for name, rows in gt2d.items():
        if rows:
            arr = np.array(rows)
            gt[name] = (arr[:, 0], [pose_from_planar(x, y, th) for _, x, y, th in arr])
    start = manifest.start_time
    vel = tuple(np.array(velocity[r.name], dtype=float).reshape(-1, 3) for r in robots)
    if start is None:
        firsts = [v[0, 0] for v in vel if len(v)] or [m.t0 for m in motions]
        if not firsts:
            firsts = [p.time for p in points] + [o.time for o in observations]
            firsts += [f.time for f in features]
        if not firsts:
            raise ValueError(f"{mpath}: the run has no odometry, relative poses or measurements")
        start = max(v[0, 0] for v in vel if len(v)) if any(len(v) for v in vel) else min(firsts)
    else:
        stamps = [t for v in vel if len(v) for t in (v[0, 0], v[-1, 0])]
        stamps += [t for m in motions for t in (m.t0, m.t1)]
        stamps += [p.time for p in points] + [o.time for o in observations]
        check_start_time(start, stamps, mpath)
    _merge_import_skips(report, manifest.meta.get("import"), mpath)
    _merge_import_skips(notes, manifest.meta.get("import"), mpath, "notes")
    return TeamRun(
        name=manifest.name,
        robots=robots,
        start_time=float(start),
        velocity=vel,
        motions=tuple(motions),
        points=tuple(points),
        observations=tuple(observations),
        groundtruth=tuple(gt[r.name] for r in robots),
        landmark_ids=ids,
        landmark_xyz=xyz,
        landmark_sigma=sig,
        landmarks_known=manifest.landmarks_file is not None,
        skips=report,
        contributions={k: v for k, v in used.items() if v},
        meta=dict(manifest.meta),
        features=tuple(features),
        scans=tuple(sorted(scans, key=lambda o: (o.time, o.robot))),
        notes=notes,
    )


def check_start_time(start: float, stamps: list, where) -> None:
    """The manifest's start_time must lie in the time span [first, last] of the run's rows (or
    before it by at most that span, at least 1 s): a clock of another run or a shifted start
    would otherwise build poses for hours nothing measured, or none at all."""
    if not stamps:
        return
    first, last = float(min(stamps)), float(max(stamps))
    if not first - max(1.0, last - first) <= start <= last:
        raise ValueError(
            f"{where}: field 'start_time' = {start} lies outside the run's rows, which span "
            f"[{first}, {last}] s"
        )


def _merge_import_skips(report: SkipReport, imported, where: Path, key: str = "skips") -> None:
    """Rows a converter (`graphloc import` of a bag) skipped before the log was written, kept in
    the manifest's meta.import.skips: reported with the log's own skips (`key` "notes": what
    it counted but used, meta.import.notes, with the run's notes)."""
    if not imported or (key == "notes" and "notes" not in imported):
        return
    skips = imported.get(key) if isinstance(imported, dict) else None
    counts = skips.get("counts") if isinstance(skips, dict) else None
    if not isinstance(counts, dict) or not all(
        isinstance(k, str) and type(n) is int and n >= 0 for k, n in counts.items()
    ):
        raise ValueError(f"{where}: field 'meta.import.{key}' must hold counts by reason")
    earlier = SkipReport(
        dict(counts),
        [
            str(m)
            for m in (skips.get("examples") if isinstance(skips.get("examples"), list) else [])
        ][: report.max_examples],
    )
    report.merge(earlier)


def _table_of(rec) -> str:
    return next(name for name, cls in TABLES.items() if type(rec) is cls)
