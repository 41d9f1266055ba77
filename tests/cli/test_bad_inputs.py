"""Issue 47, the battery of bad inputs: every reader of graphloc (log manifest, every table kind,
landmarks, scan files, MRCLAM files, ROS bag topics files, TOML configs, online checkpoints,
the `--p3p` setup JSON, `--hint`) through the command line as a
user meets it, with truncated, binary, non-UTF-8, empty, deeply nested, huge, NaN / inf,
symlinked and directory-for-a-file inputs, and names that would make a path.

Each case breaks one input of a valid run (tests/conftest.py) and runs one verb in-process
(`cli`): no traceback, an exit code of docs/outputs.md, nothing written outside `--out`
(checked by the fixture for every case), and either one `error:` line naming the file (and
line / field where there is one) or a skip counted in `graphloc validate`'s `skipped` (notes
in `notes`). Per-test timeouts bound every case (pytest-timeout).
"""

from __future__ import annotations

import json
import os
import re
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from helpers import edit_manifest, manifest
from graphloc import exitcodes

DEEP = 100_000  # nesting far beyond any recursion limit
MODERATE = 200  # parses in Python, beyond graphloc's documented depth limit


def deep_json(depth: int = DEEP) -> str:
    return "[" * depth + "]" * depth


def write_bytes(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)


BINARY = bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8))
NOT_UTF8 = b"\xff\xfe\xe4\xf6 not utf-8 \x80\x81\n"


# ---- what a case expects ----------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    """id; `fixture`: which valid run the case starts from (planar_log, camera_log, mrclam_dir);
    `breaks(root)`: how it breaks it; `argv(root, tmp)`: the command (default `validate ROOT`);
    `code`: the exit code; `error`: regex the one error line must match (code 2);
    `skip` / `note`: a reason `validate` must count (code 0); `timeout` [s]."""

    id: str
    fixture: str
    breaks: Callable
    code: int = exitcodes.BAD_INPUT
    error: str | None = None
    skip: str | None = None
    note: str | None = None
    argv: Callable | None = None
    timeout: float = 30.0
    counted: Callable | None = field(default=None)  # extra check of validate's JSON


def manifest_text(edit_text):
    """Edit manifest.json as text (for JSON no dict can hold: deep nesting, NaN)."""

    def go(root):
        path = root / "manifest.json"
        path.write_text(edit_text(path.read_text()))

    return go


def with_meta(raw: str):
    """The manifest with field 'meta' replaced by the raw JSON text `raw`."""

    def edit(text):
        data = json.loads(text)
        data["meta"] = "__RAW__"
        return json.dumps(data).replace('"__RAW__"', raw)

    return manifest_text(edit)


def robot_name(i: int, name: str):
    """Rename robot i everywhere (manifest name; rows that target it)."""

    def go(root):
        data = json.loads((root / "manifest.json").read_text())
        old = data["robots"][i]["name"]
        data["robots"][i]["name"] = name
        (root / "manifest.json").write_text(json.dumps(data))
        for p in root.rglob("*.csv"):
            text = p.read_text()
            p.write_text(re.sub(rf",{re.escape(old)},", f",{name},", text))

    return go


def sensor(robot: int, k: int, **kw):
    return manifest(lambda d: d["robots"][robot]["sensors"][k].update(kw))


def table_file(rel: str, data: bytes | Callable):
    def go(root):
        path = root / rel
        body = data(path.read_bytes()) if callable(data) else data
        if path.is_dir():
            return
        write_bytes(path, body)

    return go


def replace_line(rel: str, line_no: int, text: str):
    def go(root):
        path = root / rel
        lines = path.read_text().split("\n")
        lines[line_no - 1] = text
        path.write_text("\n".join(lines))

    return go


def edit_fields(rel: str, line_no: int, fields: dict):
    """Set fields (0-based index -> text) of one CSV line."""

    def go(root):
        path = root / rel
        lines = path.read_text().split("\n")
        row = lines[line_no - 1].split(",")
        for k, text in fields.items():
            row[k] = text
        lines[line_no - 1] = ",".join(row)
        path.write_text("\n".join(lines))

    return go


def make_dir(rel: str):
    def go(root):
        path = root / rel
        path.unlink()
        path.mkdir()

    return go


def symlink_loop(rel: str):
    def go(root):
        path = root / rel
        path.unlink()
        os.symlink(path.name, path)

    return go


def truncate_mid_row(rel: str):
    return table_file(rel, lambda b: b[: len(b) - 7])


# ---- candidates table (a camera log's climber sees the static ground robot) -------------------
CANDIDATE_HEADER = "time,sensor,target,k,score,qw,qx,qy,qz,tx,ty,tz"


def candidates(rows: list[str]):
    """Replace the camera log's markers table by a `candidates` table with `rows` (first a
    valid set at time 0.3)."""

    def go(root):
        def edit(d):
            climber = d["robots"][0]
            climber["tables"].pop("markers")
            climber["tables"]["candidates"] = "climber/candidates.csv"

        edit_manifest(root, edit)
        good = [
            "0.3,camera,ground,0,0.9,0,1,0,0,1.2,1.3,3.0",
            "0.3,camera,ground,1,0.1,0,1,0,0,1.8,1.7,3.0",
        ]
        text = "\n".join([CANDIDATE_HEADER, *good, *rows]) + "\n"
        (root / "climber" / "candidates.csv").write_text(text)

    return go


def features(rows: list[str]):
    """Give the camera log's climber a `features` table of `rows` (time,sensor,track,u,v)."""

    def go(root):
        edit_manifest(root, lambda d: d["robots"][0]["tables"].update(features="climber/f.csv"))
        text = "\n".join(["time,sensor,track,u,v", *rows]) + "\n"
        (root / "climber" / "f.csv").write_text(text)

    return go


def duplicated_marker_rows(n: int):
    """`n` copies of the first markers row inserted after it (one image with one marker seen
    n + 1 times)."""

    def go(root):
        path = root / "climber" / "markers.csv"
        lines = path.read_text().splitlines()
        path.write_text("\n".join([lines[0], *[lines[1]] * (n + 1), *lines[2:]]) + "\n")

    return go


def scan_rows(root: Path, files: dict[str, bytes | Callable]) -> None:
    """Give the camera log's climber a scanner and a `scans` table of `files` (name -> bytes
    or writer(path))."""

    def edit(d):
        d["robots"][0]["sensors"].append({"name": "lidar", "type": "scanner"})
        d["robots"][0]["tables"]["scans"] = "climber/scans.csv"

    edit_manifest(root, edit)
    rows = ["time,sensor,path"]
    for k, (name, data) in enumerate(files.items()):
        path = root / "climber" / name
        if callable(data):
            data(path)
        else:
            write_bytes(path, data)
        rows.append(f"{0.3 * (k + 1):.1f},lidar,climber/{name}")
    (root / "climber" / "scans.csv").write_text("\n".join(rows) + "\n")


def room_cloud(n: int, seed: int = 0) -> np.ndarray:
    """n points on the walls of a 6 x 4 x 3 m room around the sensor."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform([-3, -2, -1.5], [3, 2, 1.5], (n, 3))
    axis = rng.integers(0, 3, n)
    pts[np.arange(n), axis] = np.sign(pts[np.arange(n), axis]) * np.array([3.0, 2.0, 1.5])[axis]
    return pts


def ply(pts: np.ndarray) -> bytes:
    head = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(pts)}\n"
        "property double x\nproperty double y\nproperty double z\nend_header\n"
    )
    return head.encode() + np.ascontiguousarray(pts, dtype="<f8").tobytes()


def sparse_ply(path: Path, n: int) -> None:
    """A binary PLY declaring n vertices whose data is a hole (a sparse file: nothing read)."""
    head = ply(np.zeros((0, 3))).replace(b"element vertex 0", f"element vertex {n}".encode())
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        fh.write(head)
        fh.truncate(len(head) + 24 * n)


# ---- the cases --------------------------------------------------------------------------------
M = r"manifest\.json"
ESCAPE_TMP = f"/tmp/graphloc-escape-{uuid.uuid4().hex}"  # unique: nothing may ever match it
ESCAPES = ["../../escaped", ESCAPE_TMP, "a/b", "..", ".hidden", "a\\b"]
BAD_NAMES = ESCAPES + ["a\0b", "a\tb", "\x1b[31mred", "x" * 300, "rob\u00f6t", " "]

LOG_CASES = [
    # names that would decide a path, or a message
    *[
        Case(
            f"robot-name-{k}",
            "planar_log",
            robot_name(0, name),
            error=rf"{M}: robots\[0\]: field 'name'",
        )
        for k, name in enumerate(BAD_NAMES)
    ],
    *[
        Case(
            f"sensor-name-{k}",
            "planar_log",
            sensor(0, 1, name=name),
            error=rf"{M}: robots\[0\]\.sensors\[1\]: field 'name'",
        )
        for k, name in enumerate(ESCAPES)
    ],
    Case("run-name-dotdot", "planar_log", manifest(lambda d: d.update(name="../x")), error=M),
    # the manifest file itself
    Case("manifest-deep", "planar_log", with_meta(deep_json()), error=rf"{M}: .*nested deeper"),
    Case(
        "manifest-moderately-deep",
        "planar_log",
        with_meta(deep_json(MODERATE)),
        error=rf"{M}: .*nested deeper",
    ),
    Case(
        "manifest-huge",
        "planar_log",
        with_meta(json.dumps("x" * (20 << 20))),
        error=rf"{M}: .*bytes.* larger than",
    ),
    Case(
        "manifest-truncated",
        "planar_log",
        table_file("manifest.json", lambda b: b[: len(b) // 2]),
        error=rf"{M}: line \d+: invalid JSON",
    ),
    Case(
        "manifest-binary",
        "planar_log",
        table_file("manifest.json", BINARY),
        error=rf"{M}: line \d+: not UTF-8",
    ),
    Case(
        "manifest-not-utf8",
        "planar_log",
        table_file("manifest.json", NOT_UTF8),
        error=rf"{M}: line 1: not UTF-8",
    ),
    Case("manifest-empty", "planar_log", table_file("manifest.json", b""), error=rf"{M}: line 1"),
    Case("manifest-directory", "planar_log", make_dir("manifest.json"), error=r"in/log"),
    Case("manifest-symlink-loop", "planar_log", symlink_loop("manifest.json"), error=M),
    Case(
        "manifest-nan-start-time",
        "planar_log",
        manifest_text(lambda t: t.replace('"start_time": ', '"start_time": NaN, "x": ')),
        error=rf"{M}: field 'start_time'",
    ),
    # extrinsics
    *[
        Case(
            f"extrinsics-{k}",
            "planar_log",
            sensor(0, 1, extrinsics=value),
            error=rf"{M}: robots\[0\]\.sensors\[1\]: .*extrinsics.*{what}",
        )
        for k, (value, what) in {
            "rpy-nan": ({"xyz": [0, 0, 0], "rpy": [float("nan"), 0, 0]}, "rpy"),
            "rpy-inf": ({"xyz": [0, 0, 0], "rpy": [0, float("inf"), 0]}, "rpy"),
            "xyz-nan": ({"xyz": [0, float("nan"), 0], "rpy": [0, 0, 0]}, "xyz"),
            "xyz-huge": ({"xyz": [1e308, 0, 0], "rpy": [0, 0, 0]}, "xyz"),
            "planar-nan": ([0, 0, float("nan")], "theta"),
            "matrix-nan": ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, float("nan")], [0, 0, 0, 1]], ""),
            "rpy-strings": ({"xyz": [0, 0, 0], "rpy": ["a", 0, 0]}, "rpy"),
            "rpy-bools": ({"xyz": [0, 0, 0], "rpy": [True, 0, 0]}, "rpy"),
        }.items()
    ],
    # tables: bytes of every kind
    Case(
        "table-binary",
        "planar_log",
        table_file("robot1/odometry.csv", BINARY),
        error=r"robot1/odometry\.csv: line \d+: not UTF-8",
    ),
    Case(
        "table-empty",
        "planar_log",
        table_file("robot1/odometry.csv", b""),
        error=r"robot1/odometry\.csv: line 1: header",
    ),
    Case(
        "table-truncated-mid-row",
        "planar_log",
        truncate_mid_row("robot1/odometry.csv"),
        code=exitcodes.OK,
        skip="field_count",
    ),
    Case(
        "table-directory",
        "planar_log",
        make_dir("robot1/odometry.csv"),
        error=r"robot1/odometry\.csv: not a regular file",
    ),
    Case(
        "table-symlink-loop",
        "planar_log",
        symlink_loop("robot1/odometry.csv"),
        error=r"robot1/odometry\.csv",
    ),
    Case(
        "table-nul-bytes",
        "planar_log",
        replace_line("robot1/odometry.csv", 3, "1000.1\0,wheels,0.1,0.05"),
        code=exitcodes.OK,
        skip="parse",
    ),
    Case(
        "odometry-nan",
        "planar_log",
        replace_line("robot1/odometry.csv", 3, "1000.100,wheels,nan,0.05"),
        code=exitcodes.OK,
        skip="non_finite",
    ),
    Case(
        "odometry-inf-time",
        "planar_log",
        replace_line("robot1/odometry.csv", 3, "inf,wheels,0.1,0.05"),
        code=exitcodes.OK,
        skip="non_finite",
    ),
    Case(
        "range-bearing-huge",
        "planar_log",
        replace_line("robot1/range_bearing.csv", 2, "1000.250,camera,landmark:6,1e308,0.1"),
        code=exitcodes.OK,
        skip="implausible",
    ),
    Case(
        "groundtruth-csv-binary",
        "planar_log",
        table_file("robot1/groundtruth.csv", BINARY),
        error=r"robot1/groundtruth\.csv: line \d+: not UTF-8",
    ),
    # landmarks
    Case(
        "landmarks-binary",
        "planar_log",
        table_file("landmarks.csv", BINARY),
        error=r"landmarks\.csv: line \d+: not UTF-8",
    ),
    Case(
        "landmarks-nan",
        "planar_log",
        replace_line("landmarks.csv", 2, "6,nan,0.0,0,0.01,0.01,0"),
        error=r"landmarks\.csv: line 2: field 'x'",
    ),
    Case(
        "landmarks-empty-file",
        "planar_log",
        table_file("landmarks.csv", b""),
        error=r"landmarks\.csv: line 1: header",
    ),
    Case(
        "landmarks-directory",
        "planar_log",
        make_dir("landmarks.csv"),
        error=r"landmarks\.csv: not a regular file",
    ),
    # 3D tables: relative poses, TUM ground truth
    Case(
        "relative-pose3-zero-quaternion",
        "camera_log",
        edit_fields("climber/relative_pose3.csv", 3, {6: "0", 7: "0", 8: "0", 9: "0"}),
        code=exitcodes.OK,
        skip="bad_relative_pose",
    ),
    Case(
        "groundtruth-tum-binary",
        "camera_log",
        table_file("climber/groundtruth.tum", BINARY),
        error=r"climber/groundtruth\.tum: line \d+: not UTF-8",
    ),
    Case(
        "groundtruth-tum-nan",
        "camera_log",
        replace_line("climber/groundtruth.tum", 2, "0.1 nan 0 0 0 0 0 1"),
        error=r"climber/groundtruth\.tum: line 2",
    ),
    # markers: one image with a marker seen many times, every row counted
    Case(
        "markers-duplicated-rows",
        "camera_log",
        duplicated_marker_rows(10_000),
        code=exitcodes.OK,
        skip="duplicate_marker",
        counted=lambda d: (
            d["skipped"]["counts"]["duplicate_marker"] >= 10_003
            and d["rows_used"]["markers"] <= 246 - 3
        ),
    ),
    Case(
        "markers-binary",
        "camera_log",
        table_file("climber/markers.csv", BINARY),
        error=r"climber/markers\.csv: line \d+: not UTF-8",
    ),
    # candidates: every per-table check of the log format
    Case(
        "candidates-quaternion-norm-2",
        "camera_log",
        candidates(["0.6,camera,ground,0,0.9,0,2,0,0,1.2,1.3,3.0"]),
        code=exitcodes.OK,
        skip="not_unit",
    ),
    Case(
        "candidates-quaternion-zero",
        "camera_log",
        candidates(["0.6,camera,ground,0,0.9,0,0,0,0,1.2,1.3,3.0"]),
        code=exitcodes.OK,
        skip="not_unit",
    ),
    Case(
        "candidates-duplicate-k",
        "camera_log",
        candidates(
            [
                "0.6,camera,ground,0,0.5,0,1,0,0,1.2,1.3,3.0",
                "0.6,camera,ground,0,0.5,0,1,0,0,1.8,1.7,3.0",
            ]
        ),
        code=exitcodes.OK,
        skip="duplicate_candidate",
    ),
    Case(
        "candidates-unknown-target",
        "camera_log",
        candidates(["0.6,camera,nobody,0,0.9,0,1,0,0,1.2,1.3,3.0"]),
        code=exitcodes.OK,
        skip="unknown_target",
    ),
    # features: a track seen twice in one image
    Case(
        "features-duplicate-track",
        "camera_log",
        features(
            [
                "0.3,camera,0,300.0,200.0",
                "0.3,camera,0,310.0,205.0",
                "0.3,camera,1,100.0,100.0",
                "0.6,camera,1,101.0,100.0",
            ]
        ),
        code=exitcodes.OK,
        skip="duplicate_track",
        counted=lambda d: (
            d["skipped"]["counts"]["duplicate_track"] == 2 and d["rows_used"]["features"] == 2
        ),
    ),
    # scan files of a `scans` table
    Case(
        "scan-garbage",
        "camera_log",
        lambda root: scan_rows(root, {"a.ply": ply(room_cloud(300)), "b.ply": BINARY}),
        error=r"climber/scans\.csv: line 3: field 'path': \S+b\.ply",
    ),
    Case(
        "scan-empty",
        "camera_log",
        lambda root: scan_rows(root, {"a.ply": ply(room_cloud(300)), "b.ply": b""}),
        error=r"climber/scans\.csv: line 3: field 'path': \S+b\.ply",
    ),
    Case(
        "scan-truncated",
        "camera_log",
        lambda root: scan_rows(
            root, {"a.ply": ply(room_cloud(300)), "b.ply": ply(room_cloud(300))[:-100]}
        ),
        error=r"climber/scans\.csv: line 3: field 'path': \S+b\.ply: truncated",
    ),
    Case(
        "scan-beyond-the-hard-limit",
        "camera_log",
        lambda root: scan_rows(
            root, {"a.ply": ply(room_cloud(300)), "b.ply": lambda p: sparse_ply(p, 200_000_000)}
        ),
        error=r"climber/scans\.csv: line 3: field 'path': \S+b\.ply: .*limit",
    ),
    Case(
        "scan-beyond-the-point-budget",
        "camera_log",
        lambda root: scan_rows(
            root, {"a.ply": ply(room_cloud(300)), "b.ply": ply(room_cloud(1_200_000, 1))}
        ),
        code=exitcodes.OK,
        note="scan_thinned",
        timeout=90,
    ),
    # MRCLAM files
    Case(
        "mrclam-odometry-binary",
        "mrclam_dir",
        table_file("Robot1_Odometry.dat", BINARY),
        error=r"Robot1_Odometry\.dat: line \d+: not UTF-8",
    ),
    Case(
        "mrclam-measurement-empty",
        "mrclam_dir",
        table_file("Robot2_Measurement.dat", b""),
        code=exitcodes.OK,
    ),
    Case(
        "mrclam-odometry-nan",
        "mrclam_dir",
        replace_line("Robot1_Odometry.dat", 5, "1000.300 nan 0.05"),
        code=exitcodes.OK,
        skip="non_finite",
    ),
    Case(
        "mrclam-barcodes-directory",
        "mrclam_dir",
        make_dir("Barcodes.dat"),
        error=r"Barcodes\.dat: not a regular file",
    ),
]


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id) for c in LOG_CASES])
def test_bad_log_input(case: Case, request, cli, tmp_path):
    request.applymarker(pytest.mark.timeout(case.timeout))
    root = request.getfixturevalue(case.fixture)
    case.breaks(root)
    argv = case.argv(root, tmp_path) if case.argv else ["validate", root]
    got = cli(argv)
    assert got.code == case.code, (got.code, got.err[-2000:])
    if case.code == exitcodes.BAD_INPUT:
        assert len(got.err.strip().splitlines()) == 1, got.err
        if case.error:
            assert re.search(case.error, got.error_line), got.error_line
    elif case.code == exitcodes.OK and argv[0] == "validate":
        report = got.json()
        if case.skip:
            assert report["skipped"]["counts"].get(case.skip, 0) >= 1, report["skipped"]
            assert any(
                re.search(r"(\.csv|\.dat|\.tum): lines? \d+", e)
                for e in report["skipped"]["examples"]
            ), report["skipped"]["examples"]
        if case.note:
            assert report["notes"]["counts"].get(case.note, 0) >= 1, report.get("notes")
        if case.counted:
            assert case.counted(report), report["skipped"]


# ---- names never decide a path outside --out ----------------------------------------------------
@pytest.mark.timeout(60)
@pytest.mark.parametrize("name", ESCAPES, ids=[f"name{k}" for k in range(len(ESCAPES))])
def test_a_robot_name_never_writes_outside_out(planar_log, cli, tmp_path, name):
    robot_name(0, name)(planar_log)
    out = tmp_path / "deep" / "er" / "out"
    got = cli(["smooth", planar_log, "--out", out, "--no-progress"], out=out)
    assert got.code == exitcodes.BAD_INPUT and re.search(r"robots\[0\]: field 'name'", got.err)
    if name.startswith("/"):
        assert not list(Path("/tmp").glob(Path(name).name + "*"))


# ---- a ROS bag's topics file (graphloc import) and the bag's clock -------------------------------
def yaml_text(text: str):
    return lambda folder: (folder / "topics.yaml").write_text(text)


def topics_edit(edit):
    def go(folder):
        import yaml

        data = yaml.safe_load((folder / "topics.yaml").read_text())
        edit(data)
        (folder / "topics.yaml").write_text(yaml.safe_dump(data))

    return go


ALIAS_BOMB = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{b}: &{b} [{', '.join([f'*{a}'] * 10)}]\n" for a, b in zip("abcdefgh", "bcdefghi")
)
TOPICS_CASES = [
    Case(
        "topics-deep", "bag_dir", yaml_text("name: " + deep_json()), error=r"topics\.yaml: .*nested"
    ),
    Case("topics-alias-bomb", "bag_dir", yaml_text(ALIAS_BOMB), error=r"topics\.yaml: .*values"),
    Case(
        "topics-binary",
        "bag_dir",
        lambda f: write_bytes(f / "topics.yaml", BINARY),
        error=r"topics\.yaml: line \d+: not UTF-8",
    ),
    Case(
        "topics-not-utf8",
        "bag_dir",
        lambda f: write_bytes(f / "topics.yaml", NOT_UTF8),
        error=r"topics\.yaml: line 1: not UTF-8",
    ),
    Case(
        "topics-empty", "bag_dir", yaml_text(""), error=r"topics\.yaml: a topics file is a mapping"
    ),
    Case(
        "topics-syntax",
        "bag_dir",
        yaml_text("robots: [\n  - {name: a\n"),
        error=r"topics\.yaml: line \d+: not valid YAML",
    ),
    Case(
        "topics-directory",
        "bag_dir",
        lambda f: ((f / "topics.yaml").unlink(), (f / "topics.yaml").mkdir()),
        error=r"topics\.yaml: not a regular file",
    ),
    Case(
        "topics-huge",
        "bag_dir",
        yaml_text("name: " + "x" * (17 << 20)),
        error=r"topics\.yaml: \d+ bytes, larger than",
    ),
    *[
        Case(
            f"topics-robot-name-{k}",
            "bag_dir",
            topics_edit(lambda d, name=name: d["robots"][0].__setitem__("name", name)),
            error=r"topics\.yaml: robots\[0\]: field 'name'",
        )
        for k, name in enumerate(ESCAPES)
    ],
    Case(
        "topics-sensor-name-dotdot",
        "bag_dir",
        topics_edit(lambda d: d["robots"][0]["sensors"][0].__setitem__("name", "../x")),
        error=r"topics\.yaml: robots\[0\]\.sensors\[0\]: field 'name'",
    ),
]


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id) for c in TOPICS_CASES])
def test_bad_topics_file(case: Case, request, cli, tmp_path):
    request.applymarker(pytest.mark.timeout(case.timeout))
    folder = request.getfixturevalue(case.fixture)
    case.breaks(folder)
    out = tmp_path / "imported"
    got = cli(
        ["import", folder / "run.bag", "--topics", folder / "topics.yaml", "--out", out], out=out
    )
    assert got.code == case.code, (got.code, got.err[-2000:])
    assert re.search(case.error, got.error_line), got.error_line
    assert not (out / "manifest.json").exists()


@pytest.mark.timeout(60)
def test_a_bag_whose_stamps_go_backwards_counts_each_jump(bag_dir, cli, tmp_path):
    """The bag's order (receive time, jittered) differs from its header stamps': the import
    re-sorts each topic by stamp (docs/rosbag.md) and counts every message stamped before an
    earlier one of its topic, naming bag, topic and message, in `import`'s output, the log's
    manifest and `validate`'s / metrics.json's notes."""
    out = tmp_path / "imported"
    got = cli(["import", bag_dir / "run.bag", "--out", out], out=out)
    assert got.code == exitcodes.OK, got.err
    notes = got.json()["notes"]
    assert notes["counts"]["stamp_backwards"] > 0, notes
    assert notes["examples"] and all(
        re.search(r"run\.bag: topic '/rover/\S+' message \d+: stamp", e) for e in notes["examples"]
    )
    got = cli(["validate", out])
    assert got.json()["notes"]["counts"] == notes["counts"]
    got = cli(["validate", bag_dir / "run.bag"])  # the bag itself, imported on the fly
    assert got.json()["notes"]["counts"] == notes["counts"]


# ---- config files (--config) ---------------------------------------------------------------------
def config_file(data: bytes | str):
    return lambda path: write_bytes(path, data if isinstance(data, bytes) else data.encode())


CONFIG_CASES = [
    ("config-deep", config_file("keyframe_dt = " + deep_json()), r"c\.toml: .*nested"),
    ("config-moderately-deep", config_file("x = " + deep_json(MODERATE)), r"c\.toml: .*nested"),
    ("config-huge", config_file("# " + "x" * (17 << 20) + "\n"), r"c\.toml: \d+ bytes, larger"),
    ("config-binary", config_file(BINARY), r"c\.toml: line \d+: not UTF-8"),
    ("config-not-utf8", config_file(NOT_UTF8), r"c\.toml: line 1: not UTF-8"),
    ("config-syntax", config_file("keyframe_dt = = 1\n"), r"c\.toml: not valid TOML: .*line 1"),
    (
        "config-unknown-key",
        config_file("# x\nbogus = 1\n"),
        r"c\.toml: line 2: RunOptions: unknown field 'bogus'",
    ),
    (
        "config-wrong-type",
        config_file("landmarks = 3\n"),
        r"c\.toml: line 1: RunOptions\.landmarks: expected bool",
    ),
    (
        "config-table-for-value",
        config_file("[keyframe_dt]\nx = 1\n"),
        r"c\.toml: line 1: .*keyframe_dt",
    ),
    (
        "config-nan",
        config_file("sync_tolerance = nan\n"),
        r"c\.toml: line 1: RunOptions\.sync_tolerance",
    ),
    ("config-directory", lambda path: path.mkdir(), r"c\.toml: not a regular file"),
    ("config-missing", lambda path: None, r"c\.toml: required"),
]


@pytest.mark.timeout(30)
@pytest.mark.parametrize("breaks, message", [pytest.param(*c[1:], id=c[0]) for c in CONFIG_CASES])
def test_bad_config_file(planar_log, cli, tmp_path, breaks, message):
    path = tmp_path / "in" / "c.toml"
    breaks(path)
    got = cli(["validate", planar_log, "--config", path])
    assert got.code == exitcodes.BAD_INPUT, (got.code, got.err[-2000:])
    assert re.search(message, got.error_line), got.error_line


# ---- online checkpoints (--resume) ---------------------------------------------------------------
def data_file(fmt: str, version: int, body: str) -> bytes:
    """A graphloc data file with a correct header for `body` (any text)."""
    import hashlib

    raw = body.encode()
    head = {"format": fmt, "version": version, "body_bytes": len(raw)}
    head["body_sha256"] = hashlib.sha256(raw).hexdigest()
    return json.dumps(head).encode() + b"\n" + raw


CKPT = ("graphloc-online-checkpoint", 1)


def checkpoint_body(edit):
    """The template checkpoint with its body edited (and a header that matches the edit)."""

    def go(path, template):
        body = json.loads(template.read_bytes().split(b"\n", 1)[1])
        edit(body)
        path.write_bytes(data_file(*CKPT, json.dumps(body)))

    return go


CHECKPOINT_CASES = [
    (
        "steps-done-true",
        checkpoint_body(lambda b: b.update(steps_done=True)),
        r"field 'steps_done' must be an integer",
    ),
    (
        "steps-done-float",
        checkpoint_body(lambda b: b.update(steps_done=2.0)),
        r"field 'steps_done' must be an integer",
    ),
    (
        "steps-done-huge",
        checkpoint_body(lambda b: b.update(steps_done=10**30)),
        r"field 'steps_done' must be an integer",
    ),
    (
        "deep",
        lambda p, t: p.write_bytes(data_file(*CKPT, '{"x": ' + deep_json() + "}")),
        r"nested deeper",
    ),
    (
        "moderately-deep",
        lambda p, t: p.write_bytes(data_file(*CKPT, '{"x": ' + deep_json(MODERATE) + "}")),
        r"nested deeper",
    ),
    (
        "nan",
        lambda p, t: p.write_bytes(data_file(*CKPT, '{"steps_done": NaN}')),
        r"NaN is not a finite number",
    ),
    ("truncated", lambda p, t: p.write_bytes(t.read_bytes()[:-10]), r"truncated or altered"),
    (
        "altered",
        lambda p, t: p.write_bytes(t.read_bytes().replace(b'"steps_done":', b'"steps_done" :')),
        r"truncated or altered|altered or corrupted",
    ),
    ("binary", lambda p, t: p.write_bytes(BINARY), r"not a saved graphloc online checkpoint"),
    ("pickle", lambda p, t: p.write_bytes(b"\x80\x04K\x01."), r"a Python pickle"),
    ("empty", lambda p, t: p.write_bytes(b""), r"not a saved graphloc online checkpoint"),
    ("directory", lambda p, t: p.mkdir(), r"not a regular file|no such checkpoint"),
    ("huge", lambda p, t: open(p, "wb").truncate((1 << 30) + 1), r"bytes, larger than"),
]


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    "breaks, message", [pytest.param(*c[1:], id=c[0]) for c in CHECKPOINT_CASES]
)
def test_bad_checkpoint(planar_log, checkpoint_template, cli, tmp_path, breaks, message):
    path = tmp_path / "in" / "x.ckpt"
    breaks(path, checkpoint_template)
    out = tmp_path / "out"
    got = cli(["online", planar_log, "--out", out, "--resume", path, "-q"], out=out)
    assert got.code == exitcodes.BAD_INPUT, (got.code, got.err[-2000:])
    assert re.search(
        rf"x\.ckpt\S*: .*{message}|--resume \S+x\.ckpt: .*{message}", got.error_line
    ), got.error_line


# ---- fuse-maps: the --p3p setup and --hint -------------------------------------------------------
def p3p_setup(data):
    def go(folder):
        path = folder / "setup.json"
        if callable(data):
            data(path)
        else:
            write_bytes(path, data if isinstance(data, bytes) else data.encode())

    return go


GOOD_SETUP = {
    "camera": {"fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480},
    "leds": [[0.2, 0.0, 0.3], [-0.1, 0.17, 0.3], [-0.1, -0.17, 0.3]],
    "T_ceiling_camera": np.eye(4).tolist(),
    "pixels_csv": "pixels.csv",
}


def setup_with(**kw):
    return p3p_setup(json.dumps({**GOOD_SETUP, **kw}))


FUSE_INPUT_CASES = [
    (
        "p3p-deep",
        ["--p3p", "{s}/setup.json"],
        p3p_setup('{"camera": ' + deep_json() + "}"),
        r"setup\.json: .*nested",
    ),
    (
        "p3p-binary",
        ["--p3p", "{s}/setup.json"],
        p3p_setup(BINARY),
        r"setup\.json: line \d+: not UTF-8",
    ),
    (
        "p3p-not-utf8",
        ["--p3p", "{s}/setup.json"],
        p3p_setup(NOT_UTF8),
        r"setup\.json: line 1: not UTF-8",
    ),
    (
        "p3p-empty",
        ["--p3p", "{s}/setup.json"],
        p3p_setup(b""),
        r"setup\.json: line 1: invalid JSON",
    ),
    (
        "p3p-list",
        ["--p3p", "{s}/setup.json"],
        p3p_setup("[1, 2]"),
        r"setup\.json: a P3P setup is a JSON object",
    ),
    (
        "p3p-directory",
        ["--p3p", "{s}/setup.json"],
        lambda f: (f / "setup.json").mkdir(),
        r"setup\.json: not a regular file",
    ),
    ("p3p-missing", ["--p3p", "{s}/setup.json"], lambda f: None, r"setup\.json: required"),
    (
        "p3p-leds-nan",
        ["--p3p", "{s}/setup.json"],
        setup_with(leds=[[float("nan")] * 3] * 3),
        r"setup\.json: leds must be a finite",
    ),
    (
        "p3p-no-pixels-csv",
        ["--p3p", "{s}/setup.json"],
        setup_with(pixels_csv=5),
        r"setup\.json: field 'pixels_csv'",
    ),
    (
        "p3p-camera-strings",
        ["--p3p", "{s}/setup.json"],
        setup_with(camera={"fx": "a"}),
        r"setup\.json: malformed P3P setup",
    ),
    ("hint-nan", ["--hint", "nan 0 2.5 0 0 0 1"], lambda f: None, r"hint: non-finite"),
    ("hint-inf", ["--hint", "0 0 inf 0 0 0 1"], lambda f: None, r"hint: non-finite"),
    (
        "hint-huge",
        ["--hint", "1e308 0 2.5 0 0 0 1"],
        lambda f: None,
        r"hint: values must lie within",
    ),
    (
        "hint-zero-quaternion",
        ["--hint", "0 0 2.5 0 0 0 0"],
        lambda f: None,
        r"hint: quaternion .* norm 0",
    ),
    (
        "hint-six-numbers",
        ["--hint", "0 0 2.5 0 0 1"],
        lambda f: None,
        r"hint: expected 7 .* or 16 numbers, got 6",
    ),
    ("hint-text", ["--hint", "up and left"], lambda f: None, r"hint: non-numeric"),
    (
        "hint-not-rigid",
        ["--hint", " ".join(["1"] * 16)],
        lambda f: None,
        r"hint: 4x4 matrix is not a rigid",
    ),
    (
        "hint-sigma-huge",
        ["--hint", "0 0 2.5 0 0 0 1", "--hint-sigma", "1e308 1"],
        lambda f: None,
        r"hint-sigma: the rotation sigma must be at most",
    ),
    (
        "hint-sigma-nan",
        ["--hint", "0 0 2.5 0 0 0 1", "--hint-sigma", "nan 1"],
        lambda f: None,
        r"hint-sigma: expected two positive",
    ),
]


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    "extra, breaks, message", [pytest.param(*c[1:], id=c[0]) for c in FUSE_INPUT_CASES]
)
def test_bad_fuse_maps_input(scans, cli, tmp_path, extra, breaks, message):
    breaks(scans)
    out = tmp_path / "out"
    argv = ["fuse-maps", "--ground", scans / "ground", "--ceiling", scans / "ceiling", "--out", out]
    got = cli([*argv, *[a.format(s=scans) for a in extra]], out=out)
    assert got.code == exitcodes.BAD_INPUT, (got.code, got.err[-2000:])
    assert re.search(message, got.error_line), got.error_line
    assert not (out / "fusion_report.json").exists()


# ---- metrics of a robot that cannot be aligned ---------------------------------------------------
@pytest.mark.timeout(60)
def test_a_robot_that_cannot_be_aligned_has_null_metrics_with_a_reason(planar_log, cli, tmp_path):
    """The issue's case: a planar team log with one robot's odometry table left out of the
    manifest. Its dead reckoning stays at its start (every matched pose at one place), which
    evo's Umeyama alignment (--align se2) cannot align: smooth ends with code 0 and that robot's
    dead-reckoning metrics are null, with the reason."""
    edit_manifest(planar_log, lambda d: d["robots"][1]["tables"].pop("odometry"))
    path = planar_log / "robot2" / "range_bearing.csv"  # measurements at ground-truth stamps
    path.write_text(re.sub(r"^(\d+\.\d)50000,", r"\g<1>00000,", path.read_text(), flags=re.M))
    out = tmp_path / "out"
    # the log anchors the world (initial poses), so it is compared unaligned unless asked
    got = cli(["smooth", planar_log, "--out", out, "--no-progress", "--align", "se2"], out=out)
    assert got.code == exitcodes.OK, got.err
    robot = json.loads((out / "metrics.json").read_text())["per_robot"]["robot2"]
    assert robot["dead_reckoning"] is None, robot
    assert "cannot be aligned" in robot["not_evaluated"]["dead_reckoning"], robot
    assert isinstance(robot["batch"], dict) or "batch" in robot["not_evaluated"], robot


# ---- the report writers: NumPy values (the benchmark calls `fuse`, not the writers) --------------
def test_the_fusion_report_writers_take_numpy_values(tmp_path):
    """A decision whose checks hold NumPy booleans and floats (as `robust_register` makes them)
    goes through both writers of fusion_report.json; the file is JSON with plain booleans."""
    from graphloc.mapping.acceptance import Candidate, RegistrationDecision
    from graphloc.mapping.registration import Registration
    from graphloc.pipelines.map_fusion.report import write_rejection
    from graphloc.pipelines.map_fusion.types import FusionRejected

    T = np.eye(4)
    reg = Registration(T, np.float64(0.8), np.float32(0.01), np.int64(12), np.eye(6), 0.1)
    cands = tuple(Candidate(k, T, np.float32(0.1), 0.5, 0.9, np.float64(1.0), 0.0) for k in (0, 1))
    checks = {
        "cost_margin_se": (np.float64(0.4), 1.0, np.bool_(False)),
        "overlap": (np.float32(0.5), 0.1, np.bool_(True)),
    }
    decision = RegistrationDecision(
        reg, np.bool_(False), ("cost_margin_se",), checks, cands, 0, {1: "cost"}, np.eye(6), 1.0
    )
    report = write_rejection(FusionRejected(decision, T), tmp_path, extra={"n": np.int64(2)})
    saved = json.loads((tmp_path / "fusion_report.json").read_text())
    assert saved["registration_decision"]["checks"]["cost_margin_se"]["passed"] is False
    assert saved["n"] == 2 and report["status"] == "not_fused"


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.parametrize("variant", ["empty", "rectangular"])
def test_fuse_maps_writes_its_report_on_the_rooms_that_crashed_it(cli, tmp_path, variant):
    """The issue's cases: seven frames are enough for a second distinct candidate (the cost
    margin's check, whose `passed` was a NumPy bool the JSON writer refused)."""
    out = tmp_path / "out"
    argv = ["fuse-maps", "--simulate", "dual-robot-room", "--variant", variant, "--frames", "7"]
    got = cli([*argv, "--out", out], out=out)
    assert got.code in (exitcodes.OK, exitcodes.INCOMPLETE), got.err
    report = json.loads((out / "fusion_report.json").read_text())
    checks = report["registration_decision"]["checks"]
    assert isinstance(checks["cost_margin_se"]["passed"], bool), checks


# ---- two writers into one --out ------------------------------------------------------------------
@pytest.mark.timeout(180)
def test_a_second_writer_into_one_out_is_refused(planar_log, tmp_path):
    """docs/outputs.md, "One --out, several writers": while one graphloc holds --out, a second
    `graphloc smooth` into it ends with exit 2 naming the folder and writes nothing; once the
    first is gone, the folder is free again and the run's files are whole (no temporary file
    left)."""
    import subprocess
    import sys

    from graphloc.datasets.log_rows import read_tum_poses
    from graphloc.names import claim_out

    out = tmp_path / "out"
    argv = [sys.executable, "-m", "graphloc", "smooth", str(planar_log), "--out", str(out), "-q"]
    with claim_out(out):  # another process's hold, as the folder's lock sees it
        second = subprocess.run(argv, capture_output=True, timeout=170)
        assert second.returncode == exitcodes.BAD_INPUT, second.stderr.decode()[-2000:]
        assert b"another graphloc process is writing there" in second.stderr
        assert str(out).encode() in second.stderr and b"Traceback" not in second.stderr
        assert not any(out.iterdir())
    first = subprocess.run(argv, capture_output=True, timeout=170)
    assert first.returncode == exitcodes.OK, first.stderr.decode()[-2000:]
    files = sorted(p.name for p in out.iterdir())
    assert not [f for f in files if f.startswith(".")], files
    for tum in out.glob("*.tum"):
        times, _ = read_tum_poses(tum)
        assert len(times) >= 3, tum
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["run"] and (out / "decisions.csv").read_text().startswith("time,robot")


def test_claim_out_removes_a_folder_it_made_and_left_empty(tmp_path):
    from graphloc.names import claim_out

    made, kept = tmp_path / "made" / "deeper", tmp_path / "kept"
    with claim_out(made):
        assert made.is_dir()
    assert not made.exists()
    with claim_out(kept):
        (kept / "result.txt").write_text("x")
    assert (kept / "result.txt").exists()
    with pytest.raises(ValueError, match="another graphloc process"), claim_out(kept):
        with claim_out(kept):
            pass


# ---- a scan directory named by its user: any name is a run name ----------------------------------
@pytest.mark.timeout(120)
def test_a_scan_directory_with_an_odd_name_is_read(cli, tmp_path):
    folder = tmp_path / "in" / "my scans (copy) ../x"
    folder.mkdir(parents=True)
    for k in range(3):
        write_bytes(folder / f"{k:06d}.ply", ply(room_cloud(2000, k)))
    got = cli(["validate", folder])
    assert got.code == exitcodes.OK, got.err
    assert re.fullmatch(r"[A-Za-z0-9_.-]+", got.json()["run"]), got.json()["run"]
