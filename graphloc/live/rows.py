"""Rows pushed to a live team: checked field by field as the log reader checks a table, then by
the table's handler (`RowChecker`: a refused row a counted skip naming robot, table, row and
field), and held in a time window, released in time order (`TimeWindow`: `late_row`)."""

from __future__ import annotations

import heapq
import math
from collections.abc import Mapping
from dataclasses import fields

from graphloc.datasets.log_rows import TABLE_HANDLERS, RowContext, Skip
from graphloc.live.coverage import EVENT_TABLES, LIVE_TABLES, NotLiveError
from graphloc.records import SENSOR_TYPES, TABLES, columns, plausible
from graphloc.table_reader import known_target
from graphloc.textio import SkipReport, cut, shown

TABLE_RANK = {table: i for i, table in enumerate(TABLES)}  # the log reader's order of tables


class RowChecker:
    """Checks rows of a team against its `manifest`, `robots` and the handlers' `noise` defaults:
    `check(robot, table, row, n)` -> the handler's item, or None (counted in `skips`); `tables`: the
    route's (`coverage.tables_of`), an event route's item is (robot index, (time, table, item))."""

    def __init__(
        self,
        manifest,
        robots: tuple,
        noise: dict,
        landmark_ids,
        skips: SkipReport,
        tables: tuple = LIVE_TABLES,
    ):
        self.tables = tables
        self.manifest, self.robots, self.noise = manifest, robots, noise
        self.index = {r.name: i for i, r in enumerate(robots)}
        self.landmark_ids = landmark_ids
        self.skips = skips
        self.names = set(self.index)
        self.by_name = {r.name: r for r in manifest.robots}
        # per table: (column, kind, plausible range) of every column
        self.columns = {
            table: [
                (f.name, f.type, plausible(table).get(f.name))
                for f in fields(TABLES[table])
                if f.name in columns(table)
            ]
            for table in tables
        }
        self.wanted = {table: columns(table) for table in tables}

    def check(self, robot: str, table: str, row: Mapping, n: int):
        """Robot `robot`'s row n of `table` as its handler's item, None if refused (counted).
        ValueError for an unknown robot or table, `NotLiveError` for a table of the other route."""
        self.refuse(robot, table, row)
        where = f"robot {robot!r}, table {table!r}, row {n}"
        # a log source's rows (`live.tail`, `live.ros2`) name their line: provenance, no column
        extra = sorted(str(k) for k in row if k not in self.wanted[table] and k != "line")
        if extra:
            return self._skip(
                "unknown_field",
                f"{where}: field {cut(extra[0])!r} is not a column of table {table!r} "
                f"(columns: {', '.join(self.wanted[table])})",
            )
        values = {}
        for name, kind, limits in self.columns[table]:
            if name not in row:
                return self._skip("missing_field", f"{where}: field {name!r} is missing")
            value, problem = _value(row[name], kind, limits)
            if problem:
                return self._skip(problem[0], f"{where}: field {name!r}: {problem[1]}")
            values[name] = value
        manifest_robot = self.by_name[robot]
        if "sensor" in values:
            sensor = manifest_robot.sensor(values["sensor"])
            if sensor is None:
                return self._skip(
                    "unknown_sensor",
                    f"{where}: field 'sensor': robot {robot!r} has no sensor {values['sensor']!r}",
                )
            if table in SENSOR_TYPES and sensor.type != SENSOR_TYPES[table]:
                return self._skip(
                    "sensor_type",
                    f"{where}: field 'sensor': {sensor.name!r} is a {sensor.type}, table "
                    f"{table} needs a {SENSOR_TYPES[table]}",
                )
        if "target" in values and not known_target(values["target"], self.names, self.landmark_ids):
            return self._skip(
                "unknown_target",
                f"{where}: field 'target': {values['target']!r} is neither a robot nor a known "
                f"landmark",
            )
        record = TABLES[table](robot=robot, line=n, **values)
        ctx = RowContext(where, self.index[robot], self.index, self.robots, self.noise)
        if table == "markers":  # no handler: the front end checks a set's rows together
            if values["target"] not in self.index:
                return self._skip(
                    "unknown_target",
                    f"{where}: field 'target': {values['target']!r} is not a robot (markers are "
                    f"on robots with a 'markers' layout)",
                )
            item = record
        else:
            item = TABLE_HANDLERS[table].parse(record, ctx)
        if isinstance(item, Skip):
            return self._skip(item.reason, item.message)
        # an event-clocked team's rows (odometry as the wheel route's: `velocity(robot, row)`)
        if self.tables == EVENT_TABLES and table not in ("groundtruth", "odometry"):
            return (self.index[robot], (values["time"], table, item))
        return item

    def refuse(self, robot, table, row) -> None:
        """Raise for a push no row of the run can be: an unknown robot or table (ValueError), a
        table of the other route (`NotLiveError`), a row that is not a mapping of column -> value
        (TypeError); each names robot and table."""
        where = f"robot {robot!r}, table {table!r}"
        if not isinstance(robot, str) or robot not in self.index:
            raise ValueError(f"{where}: unknown robot {robot!r}; robots: {sorted(self.index)}")
        if (
            isinstance(table, str)
            and table not in self.tables
            and table in set(LIVE_TABLES + EVENT_TABLES)
        ):
            raise NotLiveError(
                f"{where}: table {table!r} is not live in this team: its tables are "
                f"{', '.join(self.tables)} (the manifest's tables chose the wheel route)"
            )
        if not isinstance(table, str) or table not in self.tables:
            raise ValueError(
                f"{where}: unknown table {table!r}; live tables: {', '.join(self.tables)}"
            )
        if not isinstance(row, Mapping):
            raise TypeError(
                f"{where}: a row is a mapping of column -> text or number (columns: "
                f"{', '.join(self.wanted[table])}), got {type(row).__name__}"
            )

    def rank(self, robot: str, table: str) -> tuple:
        """Where a row of `robot`'s `table` goes among rows of equal time: robot (manifest
        order), then table (docs/log_format.md's order), as `graphloc.io.iter_records` merges
        a log's files."""
        return (self.index[robot], TABLE_RANK[table])

    def _skip(self, reason: str, message: str) -> None:
        self.skips.add(reason, message)
        return None


def _value(raw, kind, limits) -> tuple:
    """(value, None) of one field (text or a number), or (None, (reason, message))."""
    conv = float if kind in (float, "float") else int if kind in (int, "int") else str
    if isinstance(raw, (bytes, bytearray, memoryview)):  # float(b"1") parses, str(b"a") not
        return None, ("parse", f"{cut(repr(raw))} is bytes, not text or a number (decode it)")
    if conv is str:
        return str(raw).strip(), None
    if type(raw) is float and conv is float:  # the common case, checked below
        value = raw
    elif isinstance(raw, bool):
        return None, ("parse", f"{raw!r} is not a number")
    else:
        try:
            value = conv(raw.strip() if isinstance(raw, str) else raw)
        except (TypeError, ValueError, OverflowError):
            return None, ("parse", f"cannot parse {shown(str(raw))} as {conv.__name__}")
    if conv is float and not math.isfinite(value):
        return None, ("non_finite", f"{cut(str(raw))} is not finite")
    lo, hi = limits or (-math.inf, math.inf)
    if not lo <= value <= hi:
        return None, ("implausible", f"{cut(str(raw))} is outside the plausible [{lo:g}, {hi:g}]")
    return value, None


class TimeWindow:
    """Items held until `window` seconds of newer time have arrived, then released in time order
    (ties by their `rank`, then in arrival order: so rows of equal time that arrive within the
    window come out in one order whatever order they arrived in). The release front is the
    newest time seen minus `window`; an item older than the front is late: counted
    (`late_row`) and dropped."""

    def __init__(self, window: float, skips: SkipReport):
        if isinstance(window, bool) or not isinstance(window, (int, float)):
            raise ValueError(f"window must be a number of seconds >= 0, got {window!r}")
        if not (math.isfinite(window) and window >= 0):
            raise ValueError(f"window must be finite and >= 0 [s], got {window}")
        self.window, self.skips = window, skips
        self.heap: list = []
        self.front = -math.inf  # every item before this time has been released
        self.count = 0

    def add(self, time: float, item, where: str, rank: tuple = ()) -> list:
        """Hold one item; returns the items released by it, in time order."""
        if time < self.front:
            self.skips.add(
                "late_row",
                f"{where}: time {time} arrived after the window released up to {self.front} "
                f"(window {self.window} s)",
            )
            return []
        heapq.heappush(self.heap, (time, rank, self.count, item))
        self.count += 1
        self.front = max(self.front, time - self.window)
        return self.release(self.front)

    def release(self, front: float) -> list:
        out = []
        while self.heap and self.heap[0][0] <= front:
            out.append(heapq.heappop(self.heap)[3])
        return out

    def flush(self) -> list:
        """Every held item (the run is over)."""
        self.front = math.inf
        return self.release(math.inf)
