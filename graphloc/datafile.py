"""Versioned data files (online checkpoints): one JSON header line
(format, version, body size and SHA-256) and a JSON body, written atomically; a pickle, another
format, a truncated, altered or oversized file is a ValueError naming the file."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from graphloc.names import written_whole
from graphloc.structured import MAX_DATA_BYTES, BadStructure, dumps_json, parse_json


class BadData(Exception):
    """A malformed data file (turned into ValueError naming the file by the reader)."""


def write_data_file(
    path: str | Path, fmt: str, version: int, payload: dict, allow_nan: bool = False
) -> None:
    """Write `payload` as a graphloc data file: one JSON header line (format, version, body size
    and SHA-256) and a JSON body, atomically. allow_nan: write inf/NaN as JSON constants
    (Infinity, NaN) instead of raising ValueError."""
    body = dumps_json(payload, allow_nan=allow_nan, separators=(",", ":")).encode()
    header = {
        "format": fmt,
        "version": version,
        "body_bytes": len(body),
        "body_sha256": hashlib.sha256(body).hexdigest(),
    }
    write_atomically(Path(path), dumps_json(header).encode() + b"\n" + body)


def read_data_file(
    path: str | Path, fmt: str, version: int, what: str, allow_nan: bool = False
) -> dict:
    """The JSON body of a file `write_data_file` wrote, after checking format, version, size
    and SHA-256. ValueError naming the file (and saying what is wrong) on anything else: an
    unreadable file, a pickle, another format or version, a truncated or altered body."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if not path.is_file():
            raise ValueError(f"{path}: cannot read the {what} file (not a regular file)")
        if size > MAX_DATA_BYTES:
            raise ValueError(
                f"{path}: {size} bytes, larger than the {MAX_DATA_BYTES} bytes a {what} file "
                f"may have"
            )
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the {what} file ({exc.strerror})") from None
    try:
        return _parse_data_file(data, fmt, version, what, allow_nan)
    except BadData as exc:
        raise ValueError(f"{path}: {exc}") from None


def write_atomically(path: Path, data: bytes) -> None:
    """Write `data` to a temporary file beside `path`, fsync it, rename it over `path` and fsync
    the directory: `path` holds either the old or the new content, never a partial one. An
    OSError (missing directory, disk full, `path` a directory) names `path`."""
    try:
        with written_whole(path) as tmp, open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    except OSError as exc:
        raise type(exc)(exc.errno, f"{path}: cannot write ({exc.strerror})") from None
    try:
        dir_fd = os.open(path.parent, os.O_RDONLY)
    except OSError:  # a directory that cannot be opened (some platforms): the rename is done
        return
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


def _parse_data_file(data: bytes, fmt: str, version: int, what: str, allow_nan: bool) -> dict:
    if data[:1] == b"\x80":
        raise BadData(
            f"not a saved graphloc {what}: a Python pickle (an older graphloc format or "
            f"foreign), which is not loaded because unpickling can run code; re-save it"
        )
    head, sep, body = data.partition(b"\n")
    try:
        header = json.loads(head.decode("utf-8")) if len(head) < 4096 else None
    except (UnicodeDecodeError, ValueError, RecursionError):
        header = None
    if not sep or not isinstance(header, dict) or header.get("format") != fmt:
        raise BadData(f"not a saved graphloc {what} (no {fmt} header line)")
    if header.get("version") != version:
        raise BadData(
            f"{what} format version {header.get('version')!r} unsupported (this graphloc "
            f"reads version {version})"
        )
    if header.get("body_bytes") != len(body):
        raise BadData(
            f"truncated or altered: body has {len(body)} bytes, header says "
            f"{header.get('body_bytes')!r}"
        )
    if header.get("body_sha256") != hashlib.sha256(body).hexdigest():
        raise BadData("altered or corrupted: the SHA-256 of the body does not match the header")
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BadData(f"body is not valid JSON ({exc})") from None
    try:
        # values bounded by the file's size (MAX_DATA_BYTES): JSON has no aliases
        payload = parse_json(text, "body", f"{what} body", allow_nan, max_values=MAX_DATA_BYTES)
    except BadStructure as exc:  # "body: ..." -> the file's name is put in front by the caller
        raise BadData(str(exc)) from None
    if not isinstance(payload, dict):
        raise BadData("body must be a JSON object")
    return payload
