"""Reading one table of a graphloc log: header checked, rows validated CHUNK_ROWS at a time with
NumPy (field count, numbers, plausible range, time order, sensors, targets, scan paths), each
bad row raised or counted with its file, line and field."""

from __future__ import annotations

import csv
import math
from dataclasses import fields
from pathlib import Path
from typing import Iterator

import numpy as np

from graphloc.manifest import Manifest, Robot
from graphloc.records import LANDMARK_PREFIX, SENSOR_TYPES, TABLES, columns, plausible
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


def _converter(tp):
    if tp in (float, "float"):
        return float
    if tp in (int, "int"):
        return int
    return str


CHUNK_ROWS = 1 << 16  # rows validated at once by `iter_table_chunks`


def iter_table_chunks(
    manifest: Manifest,
    robot: Robot,
    table: str,
    on_error: str = "raise",
    report: SkipReport | None = None,
    landmark_ids: set | None = None,
) -> Iterator[dict]:
    """The rows of one robot's table that pass every row check, in file order, as columns (name ->
    array or list, plus `line`), CHUNK_ROWS at a time; a bad row raises (on_error="raise", after
    the rows before it) or is counted in `report` with its file, line and field."""
    checker = LineChecker(manifest, robot, table, report, landmark_ids, on_error)
    path = checker.path
    if not check_file(path, required=False):
        raise FileNotFoundError(
            f"{path}: table {table!r} of robot {robot.name!r} listed in manifest but missing"
        )
    batch: list = []
    for block in _data_blocks(path, checker.cols):
        batch += block
        while len(batch) >= CHUNK_ROWS:
            part, batch = batch[:CHUNK_ROWS], batch[CHUNK_ROWS:]
            yield from _then_raise(checker.chunk(part), checker.state)
    if batch:
        yield from _then_raise(checker.chunk(batch), checker.state)


class LineChecker:
    """The row checks of one table (`iter_table_chunks`; `live.tail`, whose lines arrive a few at
    a time): `header(text)`, then `chunk(batch)` of (line number, text) -> accepted columns, or
    `rows(first_line, texts)` -> accepted rows as mappings."""

    def __init__(self, manifest, robot, table, report, landmark_ids=None, on_error="skip"):
        self.cols = columns(table)
        self.path = manifest.root / robot.tables[table]
        self.state = {"last_time": -math.inf}
        convs = {f.name: _converter(f.type) for f in fields(TABLES[table])}
        sink = Sink(on_error, report)
        self._args = (manifest, robot, table, self.cols, convs, sink, landmark_ids, self.state)

    def header(self, text: str) -> None:
        """ValueError naming the file and line 1 unless `text` is the table's header."""
        _check_header(self.path, text, self.cols)

    def chunk(self, batch: list) -> dict:
        return _chunk(batch, *self._args)

    def rows(self, first_line: int, texts: list[str]) -> list[dict]:
        batch = _data_only(first_line, texts)
        if not batch:
            return []
        return [{"line": line, **row} for line, row in chunk_rows(self.chunk(batch))]


def chunk_rows(chunk: dict) -> Iterator[tuple[int, dict]]:
    """(line, {column: value}) of every row of a chunk of columns."""
    names = [c for c in chunk if c != "line"]
    values = [chunk[c] if isinstance(chunk[c], list) else chunk[c].tolist() for c in names]
    for line, *row in zip(chunk["line"].tolist(), *values):
        yield line, dict(zip(names, row))


def _then_raise(chunk: dict, state: dict) -> Iterator[dict]:
    """The chunk (if it holds rows), then (on_error="raise") the error of the first bad row
    after them: a reader meets the rows before a bad row first, as if read one by one."""
    if len(chunk["line"]):
        yield chunk
    if "error" in state:
        raise ValueError(state["error"])


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
        unknown = {t for t in set(values["target"]) if not known_target(t, robots, landmark_ids)}
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
    problems.sort(key=lambda p: p[0])
    if problems and sink.on_error == "raise":  # the rows before the first bad one, then raise
        first, _, message = problems[0]
        state["error"] = message() if callable(message) else message
        accepted[first:] = False
    for _, reason, message in problems if sink.on_error == "skip" else ():
        message = (message() if callable(message) else message) if sink.wants_message() else ""
        sink.bad(reason, message)
    keep = np.flatnonzero(accepted)
    out = {
        name: ([v[i] for i in keep] if isinstance(v, list) else v[keep])
        for name, v in values.items()
    }
    out["line"] = lines[keep]
    return out


def data_lines(path: Path, cols: list[str]):
    """(line number, text) of every data line of a CSV file whose header must be `cols`
    (ValueError naming file and line 1 otherwise); blank and '#' lines are left out."""
    for block in _data_blocks(path, cols):
        yield from block


def _data_blocks(path: Path, cols: list[str]):
    """`data_lines` in lists, a block of the file at a time."""
    blocks = text_blocks(path)
    first_line, texts = next(blocks, (1, [""]))
    _check_header(path, texts[0] if texts else "", cols)
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


def _check_header(path: Path, text: str, cols: list[str]) -> None:
    """ValueError naming the file and line 1 unless `text` is the header `cols`."""
    try:
        header = [h.strip() for h in csv_fields(text)]
    except ValueError as exc:
        raise ValueError(f"{path}: line 1: header: {exc}") from None
    if header != cols:
        raise ValueError(
            f"{path}: line 1: header must be {','.join(cols)}, got {shown(','.join(header))}"
        )


def known_target(target: str, robots: set, landmark_ids: set | None) -> bool:
    if target in robots:
        return True
    if target.startswith(LANDMARK_PREFIX):
        try:
            lid = int(target[len(LANDMARK_PREFIX) :])
        except ValueError:
            return False
        return landmark_ids is None or lid in landmark_ids
    return False
