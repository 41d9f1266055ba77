"""Point-cloud files checked against their own headers before any points are used (issue 17):
Open3D only warns on a truncated or garbled PLY / PCD and returns the points it could not read
uninitialised, reads a PCD header cut short as a cloud of garbage, and its XYZ text reader
corrupts its heap on a number cut short. `ply_check` / `pcd_check` compare the data with the
header (binary: sizes; ASCII: rows of numbers), `xyz_points` reads XYZ text through NumPy,
`open3d_points` reads PLY / PCD through Open3D; each raises a ValueError naming the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d

from graphloc.textio import shown


def open3d_points(path: Path) -> np.ndarray:
    try:
        pcd = o3d.t.io.read_point_cloud(str(path))
    except RuntimeError as exc:  # e.g. a PCD header's unsupported type / size
        raise ValueError(f"{path}: Open3D cannot read it: {exc}") from None
    if "positions" not in pcd.point:
        return np.zeros((0, 3))
    return pcd.point.positions.numpy().astype(float)


def xyz_points(path: Path, max_points: int | None = None) -> np.ndarray:
    """An XYZ file (`x y z` a line) through NumPy: Open3D's text reader corrupts its heap on a
    number cut short (a truncated file ending in `1.5e`) and the interpreter aborts later.
    More than `max_points` lines is a ValueError naming the file."""
    with open(path, "rb") as fh:
        lines = [line for line in fh.read().split(b"\n") if line.strip()]
    _too_many(path, len(lines), max_points)
    _data_check_rows(path, lines, len(lines), 3)
    return np.array(b" ".join(lines).split(), dtype=float).reshape(-1, 3)


# bytes per value of the PLY / PCD scalar types (PCD: SIZE is given in the header)
_PLY_SIZES = {
    **dict.fromkeys([b"char", b"uchar", b"int8", b"uint8"], 1),
    **dict.fromkeys([b"short", b"ushort", b"int16", b"uint16"], 2),
    **dict.fromkeys([b"int", b"uint", b"float", b"int32", b"uint32", b"float32"], 4),
    **dict.fromkeys([b"double", b"float64"], 8),
}


def _header(path: Path, magic: bytes, last: bytes) -> tuple[list[list[bytes]], int] | None:
    """The split lines of a PLY / PCD header up to the line starting with `last`, and the byte
    offset of the data after it (None: not this format, or no complete header in 64 kB)."""
    with open(path, "rb") as fh:
        head = fh.read(65536)
    if not head.lstrip().startswith(magic):
        return None
    lines, offset = [], 0
    for raw in head.split(b"\n")[:-1]:
        offset += len(raw) + 1
        lines.append(raw.split())
        if raw.strip().startswith(last):
            return lines, offset
    return None


def _data_check(path: Path, offset: int, rows: int, nbytes: int | None, width=None) -> None:
    """ValueError naming the file if its data after the header (at `offset`) holds less than
    the header declares: binary data (`nbytes` given) by size; ASCII data by its non-blank
    lines, the first `width[0]` of them rows of `width[1]` numbers. Open3D itself only warns on
    a short or garbled file and returns the points it could not read uninitialised."""
    size = path.stat().st_size - offset
    if nbytes is not None:
        if size < nbytes:
            raise ValueError(
                f"{path}: truncated or corrupt: the header declares {rows} rows ({nbytes} bytes "
                f"of data), the file holds {size} bytes of data"
            )
        return
    with open(path, "rb") as fh:
        fh.seek(offset)
        lines = [line for line in fh.read().split(b"\n") if line.strip()]
    if len(lines) < rows:
        raise ValueError(
            f"{path}: truncated or corrupt: the header declares {rows} rows, the file holds "
            f"{len(lines)} data lines"
        )
    if width is not None:
        _data_check_rows(path, lines, *width)


def _data_check_rows(path: Path, lines: list, n: int, k: int) -> None:
    """ValueError naming the file and row unless the first `n` lines are each `k` numbers."""
    try:  # all rows at once; the row-by-row search only on failure
        ok = np.array(b" ".join(lines[:n]).split(), dtype=float).size == n * k
    except ValueError:
        ok = False
    if not ok:
        bad = next(i for i, line in enumerate(lines[:n]) if not _numbers(line, k))
        raise ValueError(
            f"{path}: data row {bad + 1} is not {k} numbers: {shown(lines[bad].decode('latin-1'))}"
        )


def _too_many(path: Path, points: int, max_points: int | None) -> None:
    if max_points is not None and points > max_points:
        raise ValueError(
            f"{path}: {points} points declared, beyond the limit of {max_points} points for "
            f"one scan (graphloc.mapping.io.MAX_SCAN_POINTS); thin the cloud first"
        )


def _numbers(line: bytes, k: int) -> bool:
    try:
        return np.array(line.split(), dtype=float).size == k
    except ValueError:
        return False


def ply_check(path: Path, max_points: int | None = None) -> int:
    """Check a PLY file's header (format, a vertex element, at most `max_points` vertices) and
    its data against it (`_data_check`; with list properties, at least a byte per property);
    its vertex count."""
    head = _header(path, b"ply", b"end_header")
    if head is None:
        raise ValueError(f"{path}: not a PLY file, or its header has no end_header line")
    lines, offset = head
    fmt, elements = b"", []  # [name, count, stride or None (list properties), properties]
    for parts in lines:
        if parts[:1] == [b"format"] and len(parts) > 1:
            fmt = parts[1]
        elif parts[:1] == [b"element"] and len(parts) == 3 and parts[2].isdigit():
            elements.append([parts[1], int(parts[2]), 0, 0])
        elif parts[:1] == [b"property"] and elements:
            size = _PLY_SIZES.get(parts[1]) if len(parts) == 3 else None
            stride = elements[-1][2]
            elements[-1][2] = None if size is None or stride is None else stride + size
            elements[-1][3] += 1
    vertices = next((e[1] for e in elements if e[0] == b"vertex"), None)
    if vertices is None or fmt not in (b"ascii", b"binary_little_endian", b"binary_big_endian"):
        raise ValueError(
            f"{path}: corrupt PLY header: no 'element vertex N' or an unknown format "
            f"{shown(fmt.decode('latin-1'))}"
        )
    _too_many(path, vertices, max_points)
    rows = sum(e[1] for e in elements)
    if fmt == b"ascii":  # rows of numbers: the vertices if they come first, without lists
        first = elements[0]
        width = (first[1], first[3]) if first[0] == b"vertex" and first[2] is not None else None
        _data_check(path, offset, rows, None, width)
    elif None not in [e[2] for e in elements]:
        _data_check(path, offset, rows, sum(e[1] * e[2] for e in elements))
    else:  # list properties: a lower bound, so a corrupt count is not allocated
        _data_check(path, offset, rows, sum(e[1] * e[3] for e in elements))
    return vertices


def pcd_check(path: Path, max_points: int | None = None) -> int:
    """Check a PCD file's header (POINTS, SIZE, COUNT, DATA ascii / binary / binary_compressed;
    at most `max_points` points) and its data against it (`_data_check`; compressed: the
    block's declared sizes); its point count. Open3D reads a header cut short as a cloud of
    garbage (once 153 million points)."""
    head = _header(path, b"#", b"DATA") or _header(path, b"VERSION", b"DATA")
    if head is None:  # Open3D would guess the rest (and once asked for all memory)
        raise ValueError(f"{path}: not a PCD file, or its header has no DATA line")
    lines, offset = head
    fields = {parts[0]: parts[1:] for parts in lines if parts}
    try:
        rows = int(fields[b"POINTS"][0])
        sizes = [int(v) for v in fields[b"SIZE"]]
        counts = [int(v) for v in fields.get(b"COUNT", [b"1"] * len(sizes))]
        fmt = fields[b"DATA"][0]
        width, height = int(fields[b"WIDTH"][0]), int(fields[b"HEIGHT"][0])
        if fmt not in (b"ascii", b"binary", b"binary_compressed") or len(counts) != len(sizes):
            raise ValueError
        if width * height != rows or rows < 0 or min(sizes + counts, default=0) < 1:
            raise ValueError
    except (KeyError, IndexError, ValueError):
        raise ValueError(
            f"{path}: corrupt PCD header: WIDTH x HEIGHT = POINTS, SIZE, COUNT and DATA (ascii, "
            f"binary or binary_compressed) must be given and agree"
        ) from None
    _too_many(path, rows, max_points)
    stride = sum(a * b for a, b in zip(sizes, counts))
    if fmt == b"binary_compressed":  # uint32 compressed size, uint32 uncompressed size, block
        with open(path, "rb") as fh:
            fh.seek(offset)
            packed, unpacked = np.frombuffer(fh.read(8).ljust(8, b"\0"), "<u4").tolist()
        held = path.stat().st_size - offset - 8
        # LZF expands at most ~90x: a larger ratio is a corrupt size, not a cloud to allocate
        if unpacked != rows * stride or held < packed or unpacked > 100 * (packed + 8):
            raise ValueError(
                f"{path}: truncated or corrupt: the header declares {rows} rows ({rows * stride} "
                f"bytes), the compressed block {unpacked} bytes from {packed} bytes; the file "
                f"holds {held} bytes of it"
            )
        return rows
    binary = fmt == b"binary"
    _data_check(path, offset, rows, rows * stride if binary else None, (rows, sum(counts)))
    return rows
