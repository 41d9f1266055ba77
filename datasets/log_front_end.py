"""The front-end stage of a graphloc log: the raw rows of `LogRows` -> what the team graph takes
(candidate sets, camera observations, KISS-ICP steps). It never reads a table."""

from __future__ import annotations

from dataclasses import dataclass

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
from graphloc.datasets.log_rows import LogRows


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
        grouped(rows.rows("scans")), robots, manifest, rows.skips, rows.notes
    )
    observations, marker_rows = marker_observations(
        rows.markers, robots, manifest, rows.noise, sink
    )
    candidates = grouped(rows.rows("candidates"))
    logged = candidate_observations(candidates, robots, rows.noise, manifest, sink)
    observations += logged
    observations += ellipse_observations(rows.rows("ellipses"), robots, manifest, sink)
    feature_rows = single_tracks(rows.rows("features"), manifest, sink)
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
