"""`LogTail`: a log directory a logger is still writing, tailed (its manifest, then each table's
new complete lines, checked as the log reader checks them: `table_reader.LineChecker`, a bad
row a counted skip naming file, line and field)."""

from __future__ import annotations

import heapq
import time
from dataclasses import dataclass, field
from pathlib import Path

from graphloc.manifest import MANIFEST, read_manifest
from graphloc.textio import SkipReport
from graphloc.io import is_tum, read_landmarks
from graphloc.table_reader import LineChecker


@dataclass
class _File:
    robot: str
    table: str
    path: Path
    checker: LineChecker
    offset: int = 0
    line: int = 0  # lines read so far (complete ones)
    partial: bytes = b""


@dataclass
class LogTail:
    """Tail of the log directory `root` (see the module docstring)."""

    root: Path
    skips: SkipReport = field(default_factory=SkipReport)

    def __post_init__(self):
        self.root = Path(self.root)
        self.manifest = None
        self._files: list[_File] = []
        self.rows_read = 0

    def wait_manifest(self, timeout: float, stop=lambda: False):
        """The manifest, once `manifest.json` exists and reads (a logger writing it: retried
        every 50 ms); FileNotFoundError after `timeout` s, the last error named."""
        end = time.monotonic() + timeout
        while True:
            try:
                self.open()
                return self.manifest
            except (FileNotFoundError, ValueError) as exc:
                if time.monotonic() >= end or stop():
                    raise FileNotFoundError(
                        f"{self.root / MANIFEST}: no readable manifest after {timeout:g} s ({exc})"
                    ) from None
            time.sleep(0.05)

    def open(self) -> None:
        """Read the manifest (errors name it and the field) and set up its tables' tails."""
        manifest = read_manifest(self.root)
        ids = None if manifest.landmarks_file is None else set(read_landmarks(manifest)[0].tolist())
        self._files = [
            _File(r.name, t, manifest.root / p, LineChecker(manifest, r, t, self.skips, ids))
            for r in manifest.robots
            for t, p in r.tables.items()
            if not is_tum(p)
        ]
        self.manifest = manifest

    def poll(self, timeout: float = 0.0) -> list[tuple[float, str, str, dict]]:
        """(receive time [perf_counter s], robot, table, row) of every line completed since
        the last call (none: after waiting `timeout` s, once more)."""
        out = self._poll()
        if not out and timeout > 0:
            time.sleep(timeout)
            out = self._poll()
        now = time.perf_counter()
        return [(now, *item) for item in out]

    def _poll(self) -> list[tuple[str, str, dict]]:
        if self.manifest is None:
            self.open()
        streams = []
        for f in self._files:
            rows = self._read(f)
            if rows:
                streams.append([(row["time"], f.robot, f.table, row) for row in rows])
        out = [item[1:] for item in heapq.merge(*streams, key=lambda item: item[0])]
        self.rows_read += len(out)
        return out

    def _read(self, f: _File) -> list[dict]:
        try:
            with open(f.path, "rb") as fh:
                fh.seek(f.offset)
                data = fh.read()
        except FileNotFoundError:  # not written yet
            return []
        if not data:
            return []
        f.offset += len(data)
        *complete, f.partial = (f.partial + data).split(b"\n")
        if not complete:
            return []
        texts = [c.decode("utf-8", errors="replace").rstrip("\r") for c in complete]
        first = f.line + 1
        f.line += len(texts)
        if first == 1:  # the header (a byte-order mark before it is allowed)
            f.checker.header(texts[0].lstrip("\ufeff"))
            texts, first = texts[1:], 2
        return f.checker.rows(first, texts) if texts else []
