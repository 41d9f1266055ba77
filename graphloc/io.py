"""The graphloc log format: one directory, a `manifest.json` and per-robot CSV tables
(documented in docs/log_format.md). Reader, writer and validation.

- `read_manifest(dir)` -> Manifest (robots, sensors with extrinsics, tables, landmarks;
  `graphloc.manifest`); the records of each table are in `graphloc.records`.
- `iter_records(dir, tables=...)` streams typed records time-ordered across every robot and
  table (heapq.merge over per-file iterators); every row is validated and a bad row either
  raises ValueError naming file, line and field (on_error="raise") or is counted in a
  `SkipReport` (on_error="skip") -- nothing is dropped silently. Files are UTF-8 with an
  optional byte-order mark (`graphloc.textio`). The rows are validated in chunks with NumPy
  (`iter_table_chunks`, which a reader of a large table such as `markers` takes as columns).
- `PlanarRun` is the numpy form of a planar multi-robot run (the MRCLAM loader's);
  `write_planar_run(run, dir)` writes it as a log, `write_table` one table
  (`graphloc.log_writer`). Logs are read into the one run type of the
  pipelines by `graphloc.datasets.graphloc_log.read_team_run` (`graphloc.datasets.open_run`).
"""

from __future__ import annotations

import csv
import heapq
import math
from dataclasses import fields
from pathlib import Path
from typing import Iterator

import numpy as np

from graphloc.manifest import (
    FORMAT,
    MANIFEST,
    VERSION,
    VERSIONS,
    Manifest,
    Robot,
    Sensor,
    read_manifest,
    write_manifest,
)
from graphloc.records import (
    LANDMARK_PREFIX,
    SENSOR_TYPES,
    TABLES,
    Bearing3D,
    GroundTruth2D,
    MarkerPixel,
    Odometry2D,
    PoseCandidate,
    Range,
    RangeBearing2D,
    RelativePose2D,
    RelativePose3D,
    ScanRef,
    columns,
    plausible,
)
from graphloc.log_writer import PlanarRun, write_planar_run, write_table
from graphloc.textio import (
    Sink,
    SkipReport,
    check_file,
    confined,
    csv_fields,
    cut,
    shown,
    text_blocks,
)

__all__ = [
    "FORMAT",
    "LANDMARK_PREFIX",
    "MANIFEST",
    "SENSOR_TYPES",
    "TABLES",
    "VERSION",
    "VERSIONS",
    "Bearing3D",
    "GroundTruth2D",
    "Manifest",
    "MarkerPixel",
    "Odometry2D",
    "PlanarRun",
    "PoseCandidate",
    "Range",
    "RangeBearing2D",
    "RelativePose2D",
    "RelativePose3D",
    "Robot",
    "ScanRef",
    "Sensor",
    "Sink",
    "SkipReport",
    "columns",
    "is_tum",
    "iter_records",
    "iter_table",
    "read_landmarks",
    "read_manifest",
    "write_manifest",
    "write_planar_run",
    "write_table",
]


# ---- streaming, validated reading ------------------------------------------------------------
def _converter(tp):
    if tp in (float, "float"):
        return float
    if tp in (int, "int"):
        return int
    return str


CHUNK_ROWS = 1 << 16  # rows validated at once by `iter_table_chunks`


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
        names = [c for c in chunk if c != "line"]
        values = [chunk[c] if isinstance(chunk[c], list) else chunk[c].tolist() for c in names]
        for line, *row in zip(chunk["line"].tolist(), *values):
            yield cls(robot=robot.name, line=line, **dict(zip(names, row)))


def iter_table_chunks(
    manifest: Manifest,
    robot: Robot,
    table: str,
    on_error: str = "raise",
    report: SkipReport | None = None,
    landmark_ids: set | None = None,
) -> Iterator[dict]:
    """The rows of one robot's table that pass every row check, in file order, as columns:
    dicts of column name -> float64 / int64 array or list of str, plus `line` (int64), for up
    to CHUNK_ROWS rows at a time (validated with NumPy, a row's first problem being the one
    reported). Checks: header, field count, number parsing, NaN/inf, plausible range, time
    non-decreasing (against the last accepted row), known sensor of the right type, known
    target, a `scans` path inside the run; a bad row raises (on_error="raise") or is counted
    in `report` by reason with its file, line and field."""
    sink = Sink(on_error, report)
    cls = TABLES[table]
    cols = columns(table)
    convs = {f.name: _converter(f.type) for f in fields(cls)}
    path = manifest.root / robot.tables[table]
    if not check_file(path, required=False):
        raise FileNotFoundError(
            f"{path}: table {table!r} of robot {robot.name!r} listed in manifest but missing"
        )
    state = {"last_time": -math.inf}
    batch: list = []
    for block in _data_blocks(path, cols):
        batch += block
        while len(batch) >= CHUNK_ROWS:
            part, batch = batch[:CHUNK_ROWS], batch[CHUNK_ROWS:]
            chunk = _chunk(part, manifest, robot, table, cols, convs, sink, landmark_ids, state)
            if len(chunk["line"]):
                yield chunk
    if batch:
        chunk = _chunk(batch, manifest, robot, table, cols, convs, sink, landmark_ids, state)
        if len(chunk["line"]):
            yield chunk


def _split(batch: list, cols: list[str], path: Path, problems: list) -> tuple[list, list]:
    """The rows that split into len(cols) fields (their indices) and their fields by column;
    a line that does not is appended to `problems` as (index, reason, message). A line without
    quotes, NUL or an overlong field is split at its commas (all lines of the batch at once);
    any other goes through the csv module (`graphloc.textio.csv_fields`)."""
    limit = csv.field_size_limit()
    k = len(cols)
    texts = [text for _, text in batch]
    joined = "".join(texts)
    if '"' in joined or "\0" in joined or max(map(len, texts), default=0) > limit:
        rows = []
        for i, text in enumerate(texts):
            try:
                rows.append(csv_fields(text, cols))
            except ValueError as exc:
                problems.append((i, "field_too_long", f"{path}: line {batch[i][0]}: {exc}"))
                rows.append(None)
        counts = [-1 if row is None else len(row) for row in rows]
    else:
        rows = None
        counts = [text.count(",") + 1 for text in texts]
    for i, got in enumerate(counts):
        if got not in (-1, k):
            where = f"{path}: line {batch[i][0]}"
            problems.append((i, "field_count", f"{where}: expected {k} fields, got {got}"))
    good = [i for i, got in enumerate(counts) if got == k]
    if rows is not None:
        return good, [list(c) for c in zip(*[rows[i] for i in good])] or [[] for _ in cols]
    if len(good) == len(texts):
        flat = ",".join(texts).split(",")
    else:
        flat = ",".join([texts[i] for i in good]).split(",") if good else []
    return good, [flat[j::k] for j in range(k)]


def _numbers(texts: list, conv) -> tuple[np.ndarray, np.ndarray]:
    """`texts` converted by `conv` (float or int: Python's own parsing) as float64, and a mask
    of the texts that do not parse (an integer beyond float range becomes inf)."""
    try:
        return np.array(list(map(conv, texts)), dtype=float), np.zeros(len(texts), bool)
    except (ValueError, OverflowError):
        out, bad = np.zeros(len(texts)), np.zeros(len(texts), bool)
        for k, text in enumerate(texts):
            try:
                value = conv(text)
            except ValueError:
                bad[k] = True
                continue
            try:
                out[k] = float(value)
            except OverflowError:
                out[k] = math.inf
        return out, bad


def _chunk(batch, manifest, robot, table, cols, convs, sink, landmark_ids, state) -> dict:
    """Validate one batch of (line, text): the accepted rows as columns (`iter_table_chunks`)."""
    path = manifest.root / robot.tables[table]
    n = len(batch)
    problems: list = []  # (row index, reason, message or a function making it)
    good, fields_by_col = _split(batch, cols, path, problems)
    good = np.asarray(good, dtype=np.int64)
    lines = np.fromiter((line for line, _ in batch), dtype=np.int64, count=n)
    ok = np.zeros(n, bool)
    ok[good] = True
    limits = plausible(table)
    values: dict = {}
    for name, raw in zip(cols, fields_by_col):
        conv = convs[name]
        if conv is str:
            texts = [t.strip() for t in raw]
            if len(good) == n:
                values[name] = texts
            else:
                col = [""] * n
                for i, t in zip(good, texts):
                    col[i] = t
                values[name] = col
            continue
        texts = raw  # float() and int() take the whitespace str.strip() removes
        nums, unparsed = _numbers(texts, conv)
        col = np.zeros(n)
        col[good] = nums
        values[name] = col
        lo, hi = limits.get(name, (-math.inf, math.inf))
        checks = [
            ("parse", unparsed, lambda t, conv=conv: f"cannot parse {shown(t)} as {conv.__name__}"),
            (
                "non_finite",
                ~np.isfinite(nums) & (conv is float),
                lambda t: f"{cut(t)} is not finite",
            ),
            (
                "implausible",
                ~((lo <= nums) & (nums <= hi)),
                lambda t, lo=lo, hi=hi: f"{cut(t)} is outside the plausible [{lo:g}, {hi:g}]",
            ),
        ]
        for reason, mask, text_of in checks:
            for k in np.flatnonzero(mask & ok[good]):
                i = good[k]
                line, t = int(lines[i]), texts[k].strip()
                problems.append(
                    (
                        i,
                        reason,
                        lambda line=line, t=t, name=name, text_of=text_of: (
                            f"{path}: line {line}: field '{name}': {text_of(t)}"
                        ),
                    )
                )
                ok[i] = False
    values = {  # integer columns as int64 (rows refused above hold 0)
        name: (np.where(ok, v, 0).astype(np.int64) if convs[name] is int else v)
        for name, v in values.items()
    }
    # the row's references: sensor, target, a scan's path (independent of the row's time)
    refs = np.ones(n, bool)
    ref_problem: dict = {}
    if "sensor" in values:
        known = {}
        for name in set(values["sensor"]):
            sensor = robot.sensor(name)
            if sensor is None:
                known[name] = (
                    "unknown_sensor",
                    f"field 'sensor': robot {robot.name!r} has no sensor {name!r}",
                )
            elif sensor.type != SENSOR_TYPES[table]:
                known[name] = (
                    "sensor_type",
                    f"field 'sensor': {name!r} is a {sensor.type}, table {table} needs a "
                    f"{SENSOR_TYPES[table]}",
                )
        if known:
            sensors = values["sensor"]
            for i in np.flatnonzero(ok):
                bad = known.get(sensors[i])
                if bad is not None:
                    refs[i] = False
                    ref_problem[i] = bad
    if "target" in values:
        robots = {r.name for r in manifest.robots}
        unknown = {t for t in set(values["target"]) if not _known_target(t, robots, landmark_ids)}
        if unknown:
            targets = values["target"]
            for i in np.flatnonzero(ok & refs):
                if targets[i] in unknown:
                    refs[i] = False
                    ref_problem[i] = (
                        "unknown_target",
                        f"field 'target': {targets[i]!r} is neither a robot nor a known landmark",
                    )
    if table == "scans":
        for i in np.flatnonzero(ok & refs):
            try:
                confined(manifest.root, values["path"][i], f"{path}: line {lines[i]}: field 'path'")
            except ValueError as exc:
                refs[i] = False
                ref_problem[i] = ("path_outside_run", str(exc))
    # time never goes backwards against the last accepted row (the running maximum of the rows
    # that pass every other check: a row refused for going backwards is below it anyway)
    t = values["time"]
    accepted_times = np.where(ok & refs, t, -math.inf)
    previous = np.maximum.accumulate(np.concatenate([[state["last_time"]], accepted_times]))[:-1]
    backwards = ok & (t < previous)
    for i in np.flatnonzero(backwards):
        line, ti, prev = int(lines[i]), float(t[i]), float(previous[i])
        problems.append(
            (
                i,
                "time_backwards",
                lambda line=line, ti=ti, prev=prev: (
                    f"{path}: line {line}: field 'time': {ti} goes backwards (previous {prev})"
                ),
            )
        )
    for i, (reason, message) in ref_problem.items():
        if not backwards[i]:
            where = (
                str(message)
                if reason == "path_outside_run"
                else f"{path}: line {lines[i]}: {message}"
            )
            problems.append((i, reason, where))
    accepted = ok & refs & ~backwards
    if accepted.any():
        state["last_time"] = max(state["last_time"], float(t[accepted].max()))
    for _, reason, message in sorted(problems, key=lambda p: p[0]):
        if sink.on_error == "raise" or len(sink.report.examples) < sink.report.max_examples:
            message = message() if callable(message) else message
        else:
            message = ""
        sink.bad(reason, message)
    keep = np.flatnonzero(accepted)
    out = {
        name: ([v[i] for i in keep] if isinstance(v, list) else v[keep])
        for name, v in values.items()
    }
    out["line"] = lines[keep]
    return out


def _data_lines(path: Path, cols: list[str]):
    """(line number, text) of every data line of a CSV file whose header must be `cols`
    (ValueError naming file and line 1 otherwise); blank and '#' lines are left out."""
    for block in _data_blocks(path, cols):
        yield from block


def _data_blocks(path: Path, cols: list[str]):
    """`_data_lines` in lists, a block of the file at a time."""
    blocks = text_blocks(path)
    first_line, texts = next(blocks, (1, [""]))
    header = _header(path, texts[0] if texts else "", cols)
    if header != cols:
        raise ValueError(
            f"{path}: line 1: header must be {','.join(cols)}, got {shown(','.join(header))}"
        )
    yield _data_only(first_line + 1, texts[1:])
    for first_line, texts in blocks:
        yield _data_only(first_line, texts)


def _data_only(first_line: int, texts: list[str]) -> list:
    """(line number, text) of the lines that are neither blank nor '#' comments."""
    return [
        (n, t)
        for n, t in enumerate(texts, start=first_line)
        if (t and t[0] != "#" and not t[0].isspace()) or (t.strip() and t.lstrip()[0] != "#")
    ]


def _header(path: Path, text: str, cols: list[str]) -> list[str]:
    try:
        return [h.strip() for h in csv_fields(text)]
    except ValueError as exc:
        raise ValueError(f"{path}: line 1: header: {exc}") from None


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


def _known_target(target: str, robots: set, landmark_ids: set | None) -> bool:
    if target in robots:
        return True
    if target.startswith(LANDMARK_PREFIX):
        try:
            lid = int(target[len(LANDMARK_PREFIX) :])
        except ValueError:
            return False
        return landmark_ids is None or lid in landmark_ids
    return False


LANDMARK_COLUMNS = ["id", "x", "y", "z", "sigma_x", "sigma_y", "sigma_z"]


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
    for line, text in _data_lines(path, LANDMARK_COLUMNS):
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
    """3D ground truth is a TUM file (graphloc.datasets.graphloc_log.read_tum_poses), not a CSV
    table."""
    return str(path).endswith(".tum")


def iter_records(
    root: str | Path,
    tables=None,
    robots=None,
    on_error: str = "raise",
    report: SkipReport | None = None,
) -> Iterator:
    """All records of the log (optionally only `tables` / `robots`), merged in time order across
    robots and tables (heapq.merge; ties keep robot-then-table order). Streaming: one row per file
    in memory."""
    manifest = read_manifest(root)
    # without a landmarks file (SLAM: positions unknown) every landmark id is acceptable
    landmark_ids = (
        None if manifest.landmarks_file is None else set(read_landmarks(manifest)[0].tolist())
    )
    wanted_tables = list(TABLES) if tables is None else list(tables)
    for t in wanted_tables:
        if t not in TABLES:
            raise ValueError(f"unknown table {t!r}; known: {', '.join(TABLES)}")
    known = {r.name for r in manifest.robots}
    for name in robots or []:
        if name not in known:
            raise ValueError(
                f"{manifest.root / MANIFEST}: unknown robot {name!r}; robots: {sorted(known)}"
            )
    streams = [
        iter_table(manifest, r, t, on_error, report, landmark_ids)
        for r in manifest.robots
        if robots is None or r.name in robots
        for t in wanted_tables
        if t in r.tables and not is_tum(r.tables[t])
    ]
    return heapq.merge(*streams, key=lambda rec: rec.time)
