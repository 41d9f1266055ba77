"""Reading the graphloc log format (docs/log_format.md): `iter_records` (typed records of every
robot and table in time order, each bad row raised or counted naming file, line and field) and
`read_landmarks`. The manifest is `graphloc.manifest`, the record types `graphloc.records`, the
writers `graphloc.log_writer`."""

from __future__ import annotations

import heapq
import math
from pathlib import Path
from typing import Iterator

import numpy as np

from graphloc.manifest import Manifest, Robot, read_manifest
from graphloc.records import LANDMARK_COLUMNS, TABLES, plausible
from graphloc.table_reader import chunk_rows, data_lines, iter_table_chunks
from graphloc.textio import SkipReport, check_file, csv_fields, cut, shown


# ---- streaming, validated reading ------------------------------------------------------------
def iter_table(
    manifest: Manifest,
    robot: Robot,
    table: str,
    on_error: str = "raise",
    report: SkipReport | None = None,
    landmark_ids: set | None = None,
) -> Iterator:
    """Validated records of one robot's table, in file order (the rows `iter_table_chunks`
    accepts, one record each)."""
    cls = TABLES[table]
    for chunk in iter_table_chunks(manifest, robot, table, on_error, report, landmark_ids):
        for line, row in chunk_rows(chunk):
            yield cls(robot=robot.name, line=line, **row)


def _values(
    row: list[str], cols: list[str], convs: dict, limits: dict
) -> tuple[dict, tuple | None]:
    """Typed values of one row by column, or the (reason, message) of its first problem: a value
    that does not parse, is not finite or lies outside the plausible range of its column
    (`limits`: `graphloc.records.plausible`)."""
    values = {}
    for name, raw in zip(cols, row):
        text = raw.strip()
        conv = convs[name]
        try:
            value = conv(text)
        except ValueError:
            return values, (
                "parse",
                f"field '{name}': cannot parse {shown(text)} as {conv.__name__}",
            )
        if conv is float and not math.isfinite(value):
            return values, ("non_finite", f"field '{name}': {cut(text)} is not finite")
        lo, hi = limits.get(name, (-math.inf, math.inf))
        if conv is not str and not lo <= value <= hi:
            return values, (
                "implausible",
                f"field '{name}': {cut(text)} is outside the plausible [{lo:g}, {hi:g}]",
            )
        values[name] = value
    return values, None


def read_landmarks(manifest: Manifest) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ids (L,), positions (L,3), sigmas (L,3) from the landmark table (empty arrays if the
    manifest names none). The table defines the map, so any bad row, a landmark listed twice or
    a table without rows is a ValueError naming file, line and field."""
    if manifest.landmarks_file is None:
        return np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 3))
    path = manifest.root / manifest.landmarks_file
    check_file(path, what="landmark table (manifest field 'landmarks.file')")
    convs = {name: int if name == "id" else float for name in LANDMARK_COLUMNS}
    rows: dict = {}
    for line, text in data_lines(path, LANDMARK_COLUMNS):
        where = f"{path}: line {line}"
        try:
            row = csv_fields(text, LANDMARK_COLUMNS)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
        if len(row) != len(LANDMARK_COLUMNS):
            raise ValueError(f"{where}: expected {len(LANDMARK_COLUMNS)} fields, got {len(row)}")
        values, problem = _values(row, LANDMARK_COLUMNS, convs, plausible("landmarks"))
        if problem is not None:
            raise ValueError(f"{where}: {problem[1]}")
        if values["id"] in rows:
            raise ValueError(f"{where}: field 'id': landmark {values['id']} listed twice")
        rows[values["id"]] = [values[c] for c in LANDMARK_COLUMNS[1:]]
    if not rows:
        raise ValueError(
            f"{path}: no landmark rows; a run without a landmark map names no landmark file "
            f"(its landmarks are then estimated: SLAM)"
        )
    table = np.array(list(rows.values()), dtype=float).reshape(-1, 6)
    return np.array(list(rows), dtype=int), table[:, :3], table[:, 3:]


def is_tum(path: str) -> bool:
    """3D ground truth is a TUM file (graphloc.datasets.log_rows.read_tum_poses), not a CSV
    table."""
    return str(path).endswith(".tum")


def iter_records(
    root: str | Path,
    tables=None,
    on_error: str = "raise",
    report: SkipReport | None = None,
) -> Iterator:
    """All records of the log (optionally only `tables`), merged in time order across robots
    and tables (heapq.merge; ties keep robot-then-table order). Streaming: one row per file in
    memory."""
    manifest = read_manifest(root)
    # without a landmarks file (SLAM: positions unknown) every landmark id is acceptable
    landmark_ids = (
        None if manifest.landmarks_file is None else set(read_landmarks(manifest)[0].tolist())
    )
    wanted_tables = list(TABLES) if tables is None else list(tables)
    for t in wanted_tables:
        if t not in TABLES:
            raise ValueError(f"unknown table {t!r}; known: {', '.join(TABLES)}")
    streams = [
        iter_table(manifest, r, t, on_error, report, landmark_ids)
        for r in manifest.robots
        for t in wanted_tables
        if t in r.tables and not is_tum(r.tables[t])
    ]
    return heapq.merge(*streams, key=lambda rec: rec.time)
