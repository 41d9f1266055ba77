"""Reading input files safely: a readable regular file, UTF-8 (a bad byte named by line and
column), CSV fields of any length, manifest paths confined to the run, and `SkipReport`."""

from __future__ import annotations

import csv
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Iterator

BOM = b"\xef\xbb\xbf"
SHOWN = 80  # characters of a bad value quoted in a message


# ---- skip accounting -------------------------------------------------------------------------
@dataclass
class SkipReport:
    """Counts of skipped input items by reason, plus the first `max_examples` messages
    (each naming file, line and field)."""

    counts: dict = field(default_factory=dict)
    examples: list = field(default_factory=list)
    max_examples: int = 20
    first: dict = field(default_factory=dict)  # reason -> its first message

    def add(self, reason: str, message: str, n: int = 1) -> None:
        self.counts[reason] = self.counts.get(reason, 0) + n
        self.first.setdefault(reason, message)
        if len(self.examples) < self.max_examples:
            self.examples.append(message)

    @property
    def total(self) -> int:
        return int(sum(self.counts.values()))

    def merge(self, other: "SkipReport") -> None:
        for reason, n in other.counts.items():
            self.counts[reason] = self.counts.get(reason, 0) + n
        for reason, message in other.first.items():
            self.first.setdefault(reason, message)
        self.examples.extend(other.examples[: max(0, self.max_examples - len(self.examples))])

    def as_dict(self) -> dict:
        return {
            "total": self.total,
            "counts": dict(sorted(self.counts.items())),
            "examples": list(self.examples),
            "first": dict(sorted(self.first.items())),
        }


class Sink:
    """Raise or count: the one place a bad row is handled."""

    def __init__(self, on_error: str, report: SkipReport | None):
        if on_error not in ("raise", "skip"):
            raise ValueError(f"on_error must be 'raise' or 'skip', got {on_error!r}")
        self.on_error = on_error
        self.report = report if report is not None else SkipReport()

    def bad(self, reason: str, message: str, n: int = 1) -> None:
        """Raise `message`, or count `n` items (rows, points) skipped for `reason`."""
        if self.on_error == "raise":
            raise ValueError(message)
        self.report.add(reason, message, n)

    def wants_message(self) -> bool:
        """Whether the next `bad` needs its message: it raises, or examples are still kept
        (a message costs time when millions of rows are skipped)."""
        return self.on_error == "raise" or len(self.report.examples) < self.report.max_examples


# ---- files -----------------------------------------------------------------------------------
def cut(text: str) -> str:
    """`text` cut to SHOWN characters for a message."""
    return text if len(text) <= SHOWN else text[: SHOWN - 3] + "..."


def shown(text: str) -> str:
    """`text` quoted for a message, cut to SHOWN characters."""
    return repr(cut(text))


def check_file(path: Path, required: bool = True, what: str = "file") -> bool:
    """True when `path` is a readable regular file. A missing file is FileNotFoundError when
    `required` (else False); a broken or looping symlink, a directory, a device or FIFO, or a
    file that cannot be read is always a ValueError naming the file."""
    path = Path(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        if path.is_symlink():
            raise ValueError(f"{path}: broken symbolic link (to {os.readlink(path)!r})") from None
        if required:
            raise FileNotFoundError(f"{path}: required {what} missing") from None
        return False
    except OSError as exc:  # ELOOP (symlink loop), EACCES on the directory, ...
        raise ValueError(f"{path}: cannot be read ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{path}: not a regular file")
    if not os.access(path, os.R_OK):
        raise ValueError(f"{path}: cannot be read (permission denied)")
    return True


BLOCK = 1 << 22  # bytes read and decoded at once by `text_lines`
MAX_LINE = 1 << 25  # bytes of one line: beyond, a file is not text a reader takes


def text_lines(path: Path) -> Iterator[tuple[int, str]]:
    """(line number, text without the line end) of a UTF-8 file with an optional byte-order
    mark, streamed (`text_blocks`); ValueError naming file, line and column at the first byte
    that is not UTF-8, and naming the file when it cannot be read."""
    for first, texts in text_blocks(path):
        yield from enumerate(texts, start=first)


def text_blocks(path: Path) -> Iterator[tuple[int, list[str]]]:
    """The lines of a UTF-8 file (optional byte-order mark; lines end at \\n, \\r\\n or
    \\r) in blocks of about BLOCK bytes: (number of the block's first line, texts without
    the line ends). ValueError naming file, line and column at the first byte that is not
    UTF-8, at a line longer than MAX_LINE bytes, and naming the file when it cannot be read."""
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read ({exc.strerror})") from None
    line_no = 0
    tail = b""
    with fh:
        first = True
        while True:
            try:
                block = fh.read(max(BLOCK, len(BOM)) if first else BLOCK)
            except OSError as exc:
                raise ValueError(f"{path}: cannot be read ({exc.strerror})") from None
            if not block:
                break
            if first:
                block = block[len(BOM) :] if block.startswith(BOM) else block
                first = False
            data = tail + block
            # whole lines only: up to the last \n, or a \r that is not the last byte (a \r\n
            # is never split)
            end = max(data.rfind(b"\n"), data.rfind(b"\r", 0, len(data) - 1)) + 1
            if end == 0:
                tail = data
                if len(tail) > MAX_LINE:
                    raise ValueError(
                        f"{path}: line {line_no + 1}: longer than {MAX_LINE} bytes (not a text "
                        f"file of lines?)"
                    )
                continue
            tail = data[end:]
            texts = _decoded(path, data[:end].splitlines(), line_no)
            yield line_no + 1, texts
            line_no += len(texts)
        if tail:
            yield line_no + 1, _decoded(path, tail.splitlines(), line_no)


def _decoded(path: Path, lines: list, before: int) -> list:
    """`lines` (bytes) decoded as UTF-8; ValueError naming the file, the line (counted from
    `before`) and the column of the first byte that is not UTF-8."""
    try:
        return [raw.decode("utf-8") for raw in lines]
    except UnicodeDecodeError:
        for k, raw in enumerate(lines):
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise ValueError(
                    f"{path}: line {before + k + 1}: not UTF-8 text (byte "
                    f"0x{raw[exc.start]:02x} at column {exc.start + 1})"
                ) from None
        raise


def read_text(path: Path) -> str:
    """The whole of a UTF-8 file (optional byte-order mark) as text, with `text_lines`' errors."""
    check_file(path)
    return "\n".join(text for _, text in text_lines(path))


def csv_fields(text: str, names: list[str] | None = None) -> list[str]:
    """One CSV line -> its fields. A field longer than the csv module's limit (or any other
    csv error) is a ValueError naming the field (by `names`, else by its 1-based position)."""
    try:
        return next(csv.reader([text]), [])
    except csv.Error as exc:
        limit = csv.field_size_limit()
        sizes = [len(part) for part in text.split(",")]
        i = next((k for k, n in enumerate(sizes) if n > limit), None)
        if i is None:
            raise ValueError(f"not a CSV line ({exc})") from None
        name = names[i] if names is not None and i < len(names) else f"{i + 1}"
        raise ValueError(
            f"field '{name}': {sizes[i]} characters, longer than the CSV field limit ({limit})"
        ) from None


# ---- paths named by a manifest ---------------------------------------------------------------
def confined(root: Path, rel, where: str) -> str:
    """`rel`, a path a manifest (or a table row) names, after checking that it stays inside the
    run directory `root`: a non-empty relative path, no '..' component, and (symbolic links
    resolved) inside `root`. ValueError naming `where` (manifest and field) otherwise; the
    file itself is never opened here, so nothing of a foreign file reaches a message."""
    if not isinstance(rel, str) or not rel.strip() or "\0" in rel:
        raise ValueError(f"{where} must be a path relative to the run directory, got {rel!r}")
    if PurePosixPath(rel).is_absolute() or PureWindowsPath(rel).is_absolute() or ":" in rel[:2]:
        raise ValueError(
            f"{where}: {rel!r} is an absolute path; paths are relative to the run directory"
        )
    if ".." in PurePosixPath(rel.replace("\\", "/")).parts:
        raise ValueError(f"{where}: {rel!r} leaves the run directory ('..')")
    base = Path(root).resolve()
    try:
        target = (base / rel).resolve()
    except (OSError, RuntimeError) as exc:  # a symbolic-link loop
        raise ValueError(f"{where}: {rel!r} cannot be resolved ({exc})") from None
    if not target.is_relative_to(base):
        raise ValueError(
            f"{where}: {rel!r} is a symbolic link to outside the run directory; copy the file "
            f"into the run"
        )
    return rel
