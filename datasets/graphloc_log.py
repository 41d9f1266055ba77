"""A graphloc log directory (docs/log_format.md) -> `graphloc.run.TeamRun`: parsing
(`log_rows.read_log_rows`), the front-end stage (`run_front_ends`: candidate sets, camera
observations, KISS-ICP steps; it never reads a table), then the start time checked and the
converter's skips merged."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from graphloc.datasets.camera_tables import (
    ellipse_observations,
    feature_observations,
    single_tracks,
)
from graphloc.datasets.log_observations import (
    candidate_observations,
    marker_observations,
    scan_odometry,
)
from graphloc.datasets.log_rows import LogRows, read_log_rows
from graphloc.manifest import MANIFEST
from graphloc.textio import SkipReport
from graphloc.run import TeamRun, pose_from_planar


@dataclass(frozen=True)
class FrontEndOutput:
    """What the front-ends made of a log's rows: KISS-ICP steps (`Motion`) and the scans they
    came from (`ScanObservation`, by time), candidate sets (`CandidateObservation`: P3P,
    logged, circles; by time, then observer), feature pixels (`FeatureObservation`) and the
    rows they used per table (`markers`, `candidates`, `features`: counted here, not when
    parsed)."""

    scan_motions: tuple
    scans: tuple
    observations: tuple
    features: tuple
    used: dict


def grouped(pairs: list) -> dict:
    """(key, row) pairs -> key -> [rows], keys in order of first appearance."""
    out: dict = {}
    for key, row in pairs:
        out.setdefault(key, []).append(row)
    return out


def run_front_ends(rows: LogRows) -> FrontEndOutput:
    """Every front-end over `rows`; each refused row or set is counted in `rows.sink` (or
    raised)."""
    robots, manifest, sink = rows.robots, rows.manifest, rows.sink
    scan_motions, scans = scan_odometry(
        grouped(rows.tables["scans"]), robots, manifest, rows.skips, rows.notes
    )
    observations, marker_rows = marker_observations(
        rows.markers, robots, manifest, rows.noise, sink
    )
    candidates = grouped(rows.tables["candidates"])
    logged = candidate_observations(candidates, robots, rows.noise, manifest, sink)
    observations += logged
    observations += ellipse_observations(rows.tables["ellipses"], robots, manifest, sink)
    feature_rows = single_tracks(rows.tables["features"], manifest, sink)
    features = feature_observations(feature_rows, robots, manifest, rows.noise)
    observations.sort(key=lambda o: (o.time, o.robot))
    used = {
        "markers": marker_rows,
        "candidates": sum(len(o.candidates) for o in logged),
        "features": len(feature_rows),
    }
    return FrontEndOutput(
        tuple(scan_motions),
        tuple(sorted(scans, key=lambda o: (o.time, o.robot))),
        tuple(observations),
        tuple(features),
        used,
    )


def read_team_run(
    root: str | Path,
    on_error: str = "skip",
    defaults: dict | None = None,
    overrides: dict | None = None,
) -> TeamRun:
    """A graphloc log directory -> TeamRun: `read_log_rows` (its arguments: `on_error`,
    noise `defaults` and `overrides`), then `run_front_ends`, then `team_run`."""
    rows = read_log_rows(root, on_error, defaults, overrides)
    return team_run(rows, run_front_ends(rows))


def team_run(rows: LogRows, front: FrontEndOutput) -> TeamRun:
    """A log's parsed rows and what the front-ends made of them as one TeamRun. The start time
    is the manifest's (checked against the rows' span, `check_start_time`), else the latest
    first wheel-odometry stamp of a robot, else the earliest stamp of any row."""
    manifest, robots = rows.manifest, rows.robots
    mpath = manifest.root / MANIFEST
    motions = rows.tables["motions"] + list(front.scan_motions)
    points = rows.tables["points"]
    observations, features = front.observations, front.features
    velocity = grouped(rows.tables["velocity"])
    vel = tuple(
        np.array(velocity.get(i, []), dtype=float).reshape(-1, 3) for i in range(len(robots))
    )
    gt = dict(rows.groundtruth)
    for ri, samples in grouped(rows.tables["groundtruth"]).items():
        arr = np.array(samples)
        gt[robots[ri].name] = (arr[:, 0], [pose_from_planar(x, y, th) for _, x, y, th in arr])
    start = manifest.start_time
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
    _merge_import_skips(rows.skips, manifest.meta.get("import"), mpath)
    _merge_import_skips(rows.notes, manifest.meta.get("import"), mpath, "notes")
    ids, xyz, sig = rows.landmarks
    used = {table: n + front.used.get(table, 0) for table, n in rows.used.items()}
    return TeamRun(
        name=manifest.name,
        robots=robots,
        start_time=float(start),
        velocity=vel,
        motions=tuple(motions),
        points=tuple(points),
        observations=observations,
        groundtruth=tuple(gt[r.name] for r in robots),
        landmark_ids=ids,
        landmark_xyz=xyz,
        landmark_sigma=sig,
        landmarks_known=manifest.landmarks_file is not None,
        skips=rows.skips,
        contributions={k: n for k, n in used.items() if n},
        meta=dict(manifest.meta),
        features=features,
        scans=front.scans,
        notes=rows.notes,
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
    examples = skips.get("examples")
    examples = [str(m) for m in examples] if isinstance(examples, list) else []
    report.merge(SkipReport(dict(counts), examples[: report.max_examples]))
