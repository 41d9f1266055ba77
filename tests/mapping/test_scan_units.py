"""Issue 17, point clouds: the two robots' scans must be in one unit before any registration
(`graphloc.mapping.io.check_scan_units`). Ceiling scans in centimetres or millimetres beside
ground scans in metres, or one scan of a sequence in another unit, are a ValueError naming the
files and the ratio; scans of one room in one unit pass, whatever that room's size. A PLY / PCD
file whose data do not match its header (truncated, garbled rows) is a ValueError naming it --
Open3D only warns and returns the unread points uninitialised. LED pixel tables and TUM
trajectories, whatever their rows hold, are read or name the file."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from hypothesis import given
from hypothesis import strategies as st

from graphloc.mapping.io import MAX_SCALE_RATIO, check_scan_units, read_points, scan_extent
from helpers import FAST


def room_scans(rng, n: int, size=(6.0, 4.0, 3.0), points: int = 300) -> list[np.ndarray]:
    """n scans of the walls of a box room of `size` [m] around a sensor near its centre."""
    half = np.asarray(size) / 2.0
    out = []
    for _ in range(n):
        pts = rng.uniform(-half, half, (points, 3))
        axis = rng.integers(0, 3, points)
        rows = np.arange(points)
        pts[rows, axis] = np.sign(pts[rows, axis]) * half[axis]
        out.append(pts + rng.normal(0.0, 0.2, 3))
    return out


def files(robot: str, n: int) -> list[Path]:
    return [Path(robot) / f"{k:06d}.ply" for k in range(n)]


@FAST
@given(
    seed=st.integers(0, 2**16),
    size=st.tuples(*[st.floats(0.5, 40.0)] * 3),
    factor=st.floats(1e-4, 1e4),
    n=st.tuples(st.integers(1, 5), st.integers(1, 5)),
)
def test_scale_ratio_beyond_the_limit_is_an_error_naming_both_files(seed, size, factor, n):
    rng = np.random.default_rng(seed)
    ground = room_scans(rng, n[0], size)
    ceiling = [p * factor for p in room_scans(rng, n[1], size)]
    want = np.median([scan_extent(p) for p in ceiling]) / np.median(
        [scan_extent(p) for p in ground]
    )
    seqs = {"ground": (ground, files("g", n[0])), "ceiling": (ceiling, files("c", n[1]))}
    if 1.0 / MAX_SCALE_RATIO <= want <= MAX_SCALE_RATIO:
        got = check_scan_units(seqs)
        assert got["largest_over_smallest"] == pytest.approx(max(want, 1.0 / want))
        assert got["extent_m"]["ceiling"] == pytest.approx(want * got["extent_m"]["ground"])
        return
    with pytest.raises(ValueError) as err:
        check_scan_units(seqs)
    msg = str(err.value)
    hi, lo, ratio = ("c", "g", want) if want > 1 else ("g", "c", 1.0 / want)
    where = rf"^{hi}/0000\d\d\.ply and {lo}/0000\d\d\.ply: .* is " + re.escape(f"{ratio:.3g} x ")
    assert re.search(where, msg), msg
    assert "not in one unit" in msg


@pytest.mark.parametrize(
    "factor, hint", [(100.0, "ratio near 100: centimetres?"), (1000.0, "millimetres?")]
)
def test_ceiling_in_another_unit_names_the_unit(factor, hint):
    rng = np.random.default_rng(1)
    ground, ceiling = room_scans(rng, 3), [p * factor for p in room_scans(rng, 3)]
    with pytest.raises(ValueError, match=re.escape(hint)):
        check_scan_units({"ground": (ground, files("g", 3)), "ceiling": (ceiling, files("c", 3))})


def test_one_scan_in_another_unit_names_its_file():
    rng = np.random.default_rng(2)
    ground, ceiling = room_scans(rng, 4), room_scans(rng, 4)
    ceiling[2] = ceiling[2] * 100.0
    with pytest.raises(ValueError, match=r"^c/000002\.ply: extent \S+ is \S+ x the median .* 4 "):
        check_scan_units({"ground": (ground, files("g", 4)), "ceiling": (ceiling, files("c", 4))})
    ground[0] = ground[0] / 1000.0
    with pytest.raises(ValueError, match=r"^g/000000\.ply: .*ratio near 1000: millimetres\?"):
        check_scan_units(
            {"ground": (ground, files("g", 4)), "c": (room_scans(rng, 4), files("c", 4))}
        )


# ---- point-cloud files whose data do not match their header (Open3D only warns on them and
# returns the unread points uninitialised) ------------------------------------------------------
def _cloud(path: Path, ascii_: bool) -> bytes:
    pts = np.random.default_rng(3).uniform(-3.0, 3.0, (100, 3))
    cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(pts))
    o3d.t.io.write_point_cloud(str(path), cloud, write_ascii=ascii_)
    return path.read_bytes()


def _garble_row(data: bytes) -> bytes:
    lines = data.split(b"\n")
    end = next(k for k, ln in enumerate(lines) if ln.startswith((b"end_header", b"DATA")))
    lines[end + 5] = b"1.5 x 2.5"
    return b"\n".join(lines)


@pytest.mark.parametrize("suffix", [".ply", ".pcd"])
@pytest.mark.parametrize(
    "ascii_, breaks, reason",
    [
        (False, lambda d: d[: len(d) // 2], r"declares 100 rows \(2400 bytes of data\), the file"),
        (True, lambda d: d[: len(d) // 2], r"declares 100 rows, the file holds \d\d data lines"),
        (True, _garble_row, r"data row 5 is not 3 numbers: '1.5 x 2.5'"),
    ],
)
def test_clouds_whose_data_do_not_match_their_header_are_errors(
    tmp_path, suffix, ascii_, breaks, reason
):
    path = tmp_path / f"scan{suffix}"
    path.write_bytes(breaks(_cloud(path, ascii_)))
    with pytest.raises(ValueError, match=re.escape(str(path)) + r": .*" + reason):
        read_points(path)


def _xyz(path: Path, ascii_: bool) -> bytes:
    np.savetxt(path, np.random.default_rng(3).uniform(-3.0, 3.0, (100, 3)))
    return path.read_bytes()


FILE_CASES = [  # (file name, writer, how it is broken, the exact reason)
    (  # Open3D's text reader corrupted its heap on this; the interpreter aborted later
        "scan.xyz",
        _xyz,
        lambda d: d[: d.index(b"e", 1000) + 1],
        r"data row \d+ is not 3 numbers: '[^']*e'",
    ),
    ("scan.xyz", _xyz, lambda d: d.replace(b"\n", b" 7\n", 1), r"data row 1 is not 3 numbers"),
    (  # Open3D read a PCD header cut short as a cloud of garbage
        "scan.pcd",
        _cloud,
        lambda d: d[: d.index(b"DATA")],
        r"not a PCD file, or its header has no DATA line",
    ),
    ("scan.pcd", _cloud, lambda d: d.replace(b"SIZE 8 8 8", b"SIZE 8 8"), r"corrupt PCD header"),
]


@pytest.mark.parametrize("name, write, breaks, reason", FILE_CASES)
def test_broken_xyz_and_pcd_headers_are_errors(tmp_path, name, write, breaks, reason):
    path = tmp_path / name
    path.write_bytes(breaks(write(path, False)))
    with pytest.raises(ValueError, match=re.escape(str(path)) + r": .*" + reason):
        read_points(path)


@FAST
@given(
    kind=st.sampled_from(
        ["binary.ply", "ascii.ply", "binary.pcd", "ascii.pcd", "packed.pcd", "xyz"]
    ),
    edits=st.lists(
        st.tuples(
            st.sampled_from(["cut", "flip", "insert"]),
            st.floats(0, 1),
            st.binary(min_size=1, max_size=8),
        ),
        min_size=1,
        max_size=4,
    ),
)
def test_read_points_returns_points_or_names_the_file(tmp_path_factory, kind, edits):
    """Cut, flip or insert bytes anywhere in a valid scan file (header included): read_points
    returns (N,3) points within +-MAX_COORDINATE or raises a ValueError naming the file -- never
    another exception, never an abort of the interpreter."""
    from graphloc.mapping.io import MAX_COORDINATE

    path = tmp_path_factory.mktemp("c") / f"scan.{kind.split('.')[-1]}"
    pts = np.random.default_rng(4).uniform(-3.0, 3.0, (40, 3))
    if kind == "xyz":
        np.savetxt(path, pts)
    else:
        cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(pts))
        how = {"write_ascii": kind.startswith("ascii"), "compressed": kind == "packed.pcd"}
        o3d.t.io.write_point_cloud(str(path), cloud, **how)
    data = bytearray(path.read_bytes())
    for op, where, blob in edits:
        k = int(where * (len(data) - 1)) if data else 0
        if op == "cut":
            data = data[:k]
        elif op == "flip" and data:
            data[k] ^= blob[0] or 1
        else:
            data[k:k] = blob
    path.write_bytes(bytes(data))
    try:
        got = read_points(path)
    except ValueError as exc:
        assert str(path) in str(exc), exc
        return
    assert got.ndim == 2 and got.shape[1] == 3 and len(got) > 0
    finite = got[np.isfinite(got).all(axis=1)]
    assert not len(finite) or np.abs(finite).max() <= MAX_COORDINATE


# ---- the other mapping tables: LED pixels (fuse-maps --p3p) and TUM trajectories -------------
LED_TABLE = "frame,time,led,u,v\n" + "".join(
    f"{f},{f * 0.1},{k},{100 + k}.5,{200 + f}.25\n" for f in range(4) for k in range(3)
)
TUM_TABLE = "".join(f"{t * 0.1} {t} 0 0 0 0 0 1\n" for t in range(6))
TOKENS = ["nan", "inf", "1e308", "-1", "0", "", "x", ",", " ", "\x00", "\xe4", "9" * 300, "#", "3"]


@FAST
@given(
    which=st.sampled_from(["led", "tum"]),
    edits=st.lists(
        st.tuples(st.floats(0, 1), st.sampled_from(["token", "drop", "repeat", "cut"]), st.data()),
        min_size=1,
        max_size=3,
    ),
)
def test_led_pixels_and_tum_return_or_name_the_file(tmp_path_factory, which, edits):
    from graphloc.mapping.io import read_led_pixels, read_tum

    sep = "," if which == "led" else " "
    lines = (LED_TABLE if which == "led" else TUM_TABLE).split("\n")
    for where, op, data in edits:
        i = int(where * (len(lines) - 1))
        if op == "token":
            parts = lines[i].split(sep)
            parts[data.draw(st.integers(0, len(parts) - 1))] = data.draw(st.sampled_from(TOKENS))
            lines[i] = sep.join(parts)
        elif op == "drop" and len(lines) > 1:
            lines.pop(i)
        elif op == "repeat":
            lines.insert(i, lines[i])
        else:
            lines[i] = lines[i][: data.draw(st.integers(0, len(lines[i])))]
    path = tmp_path_factory.mktemp("t") / ("pixels.csv" if which == "led" else "poses.tum")
    path.write_text("\n".join(lines))
    try:
        got = read_led_pixels(path, 4) if which == "led" else read_tum(path)
    except ValueError as exc:
        assert str(path) in str(exc), exc
        return
    if which == "led":
        assert got.shape == (4, 3, 2)
    else:
        assert (
            np.isfinite(got[0]).all() and np.isfinite(got[1]).all() and (np.diff(got[0]) > 0).all()
        )
