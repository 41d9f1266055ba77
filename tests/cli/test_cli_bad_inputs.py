"""Issue 17, "Done when": malformed inputs through the command line, as a user meets them. Each
case writes one malformed input, runs the verb and checks the exit code (graphloc.exitcodes)
and that the message names the place -- file, line and field, the manifest field, or the
option -- or that the row is a counted, reported skip. Never a traceback, never a foreign
file's content in a message."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest

from graphloc import exitcodes
from graphloc.cli import main
from helpers import edit_manifest, manifest, scan_dirs, write_cloud
from helpers import write_planar_log as planar_log

# ---- inputs ------------------------------------------------------------------------------------


def edit_line(path: Path, line_no: int, text: bytes | str) -> None:
    lines = path.read_bytes().split(b"\n")
    lines[line_no - 1] = text if isinstance(text, bytes) else text.encode()
    path.write_bytes(b"\n".join(lines))


def set_table(robot: int, table: str, rel: str):
    return lambda d: d["robots"][robot]["tables"].__setitem__(table, rel)


def symlink_out(root: Path) -> None:
    os.symlink("/etc/passwd", root / "robot1" / "evil.csv")
    edit_manifest(root, set_table(0, "odometry", "robot1/evil.csv"))


def scan_table(root: Path, path: str) -> None:
    def edit(d):
        d["robots"][0]["sensors"].append({"name": "lidar", "type": "scanner"})
        d["robots"][0]["tables"]["scans"] = "robot1/scans.csv"

    edit_manifest(root, edit)
    (root / "robot1" / "scans.csv").write_text(f"time,sensor,path\n1000.5,lidar,{path}\n")


def scan_in_millimetres(root: Path) -> None:
    rng = np.random.default_rng(1)
    write_cloud(root / "scans" / "0.ply", rng.uniform(-3000, 3000, (200, 3)))
    scan_table(root, "scans/0.ply")


def odometry_row(text: bytes | str):
    return lambda root: edit_line(root / "robot1" / "odometry.csv", 3, text)


def sensor_params(**params):
    return manifest(lambda d: d["robots"][0]["sensors"][1]["params"].update(params))


# (id, how to break the log, exit code, stream, regex the message must match)
LOG_CASES = [
    (
        "table-absolute-path",
        manifest(set_table(0, "odometry", "/etc/passwd")),
        exitcodes.BAD_INPUT,
        "err",
        r"manifest\.json: robots\[0\]: field 'tables\.odometry': '/etc/passwd' is an absolute",
    ),
    (
        "table-dotdot",
        manifest(set_table(1, "groundtruth", "../mr/Robot2_Groundtruth.dat")),
        exitcodes.BAD_INPUT,
        "err",
        r"robots\[1\]: field 'tables\.groundtruth': '\.\./mr/Robot2_Groundtruth\.dat' leaves "
        r"the run directory",
    ),
    (
        "table-symlink-out",
        symlink_out,
        exitcodes.BAD_INPUT,
        "err",
        r"field 'tables\.odometry': 'robot1/evil\.csv' is a symbolic link to outside the run",
    ),
    (
        "landmarks-absolute-path",
        manifest(lambda d: d.__setitem__("landmarks", {"file": "/etc/passwd"})),
        exitcodes.BAD_INPUT,
        "err",
        r"manifest\.json: field 'landmarks\.file': '/etc/passwd' is an absolute path",
    ),
    (
        "scan-row-path-outside",
        lambda root: scan_table(root, "../../etc/passwd.pcd"),
        exitcodes.OK,
        "out",
        r"robot1/scans\.csv: line 2: field 'path': '\.\./\.\./etc/passwd\.pcd' leaves the run",
    ),
    (
        "log-scan-in-millimetres",
        scan_in_millimetres,
        exitcodes.BAD_INPUT,
        "err",
        r"robot1/scans\.csv: line 2: field 'path': \S+/scans/0\.ply: median range \S+ is outside "
        r"the plausible \[0\.05, 500\] m of a scan in metres \(in millimetres\?\)",
    ),
    (
        "tables-as-list",
        manifest(lambda d: d["robots"][0].__setitem__("tables", ["odometry"])),
        exitcodes.BAD_INPUT,
        "err",
        r"robots\[0\]: field 'tables' must be a JSON object",
    ),
    (
        "table-not-utf8",
        odometry_row(b"\xe4\xf6,wheels,0.1,0.05"),
        exitcodes.BAD_INPUT,
        "err",
        r"robot1/odometry\.csv: line 3: not UTF-8 text \(byte 0xe4 at column 1\)",
    ),
    (
        "manifest-not-utf8",
        lambda root: (root / "manifest.json").write_bytes(
            (root / "manifest.json").read_bytes().replace(b'"robot2"', b'"robot\xe4"', 1)
        ),
        exitcodes.BAD_INPUT,
        "err",
        r"manifest\.json: line \d+: not UTF-8 text \(byte 0xe4 at column \d+\)",
    ),
    (
        "csv-field-over-the-limit",
        odometry_row("1000.100,wheels," + "1" * 200_000 + ",0.05"),
        exitcodes.OK,
        "out",
        r"robot1/odometry\.csv: line 3: field 'v': 200000 characters, longer than the CSV field "
        r"limit \(131072\)",
    ),
    (
        "speed-1e308",
        odometry_row("1000.100,wheels,1e308,0.05"),
        exitcodes.OK,
        "out",
        r"robot1/odometry\.csv: line 3: field 'v': 1e308 is outside the plausible \[-100, 100\]",
    ),
    (
        "initial-pose-1e308",
        manifest(lambda d: d["robots"][0].__setitem__("initial_pose", [1e308, 0, 0])),
        exitcodes.BAD_INPUT,
        "err",
        r"robots\[0\]: field 'initial_pose' must be 3 or 7 finite numbers",
    ),
    (
        "start-time-shifted",
        manifest(lambda d: d.__setitem__("start_time", d["start_time"] + 1e6)),
        exitcodes.BAD_INPUT,
        "err",
        r"manifest\.json: field 'start_time' = \S+ lies outside the run's rows",
    ),
    (
        "sensor-sigma-negative",
        sensor_params(bearing_sigma=-1),
        exitcodes.BAD_INPUT,
        "err",
        r"robots\[0\]\.sensors\[1\]: params field 'bearing_sigma' must be a number, positive",
    ),
    (
        "candidate-sigmas-zero",
        sensor_params(candidate_sigmas=[0, 0.1]),
        exitcodes.BAD_INPUT,
        "err",
        r"robots\[0\]\.sensors\[1\]: params field 'candidate_sigmas' must be a list of 2",
    ),
    (
        "extrinsics-not-numbers",
        manifest(lambda d: d["robots"][0]["sensors"][1].__setitem__("extrinsics", ["a", 0, 0])),
        exitcodes.BAD_INPUT,
        "err",
        r"robots\[0\]\.sensors\[1\]: extrinsics must be numbers",
    ),
    (
        "landmark-table-empty",
        lambda root: (root / "landmarks.csv").write_text("id,x,y,z,sigma_x,sigma_y,sigma_z\n"),
        exitcodes.BAD_INPUT,
        "err",
        r"landmarks\.csv: no landmark rows",
    ),
    (
        "landmark-sigma-negative",
        lambda root: edit_line(root / "landmarks.csv", 2, "6,2.0,0.0,0,-1,0.01,0"),
        exitcodes.BAD_INPUT,
        "err",
        r"landmarks\.csv: line 2: field 'sigma_x': -1 is outside the plausible \[0, 1e\+06\]",
    ),
    (
        "table-missing",
        lambda root: (root / "robot2" / "range_bearing.csv").unlink(),
        exitcodes.BAD_INPUT,
        "err",
        r"robot2/range_bearing\.csv: table 'range_bearing' of robot 'robot2' listed in manifest "
        r"but missing",
    ),
    (
        "table-symlink-loop",
        lambda root: (
            (root / "robot2" / "range_bearing.csv").unlink(),
            os.symlink("range_bearing.csv", root / "robot2" / "range_bearing.csv"),
        ),
        exitcodes.BAD_INPUT,
        "err",
        r"field 'tables\.range_bearing': 'robot2/range_bearing\.csv' cannot be resolved",
    ),
]


def run_cli(argv, capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return code, out, err


@pytest.mark.parametrize(
    "name, breaks, code, stream, message", LOG_CASES, ids=[c[0] for c in LOG_CASES]
)
def test_malformed_log_gives_its_exit_code_and_names_the_place(
    tmp_path, capsys, name, breaks, code, stream, message
):
    root = planar_log(tmp_path)
    breaks(root)
    got, out, err = run_cli(["validate", root], capsys)
    assert got == code, (out, err)
    text = err if stream == "err" else out
    assert re.search(message, text), text[-2000:]
    assert "root:x:0" not in out + err  # a foreign file's content never reaches a message
    if code != exitcodes.OK:
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("graphloc validate: error: "), err
    else:  # a counted, reported skip
        assert json.loads(out)["skipped"]["total"] >= 1


# ---- options and --out ---------------------------------------------------------------------------
OPTION_CASES = [  # the message names the option (as --flag, config key or field) and the value
    (["--kernel", "bogus:x"], r"\bkernel\b.*'bogus:x'"),
    (["--candidate-kernel", "cauchy:-1"], r"candidate.kernel\b.*'cauchy:-1'"),
    (["--odometry-kernel", "welsh"], r"odometry.kernel\b.*'welsh'"),
    (["--bearing-sigma", "nan"], r"bearing.sigma\b.*\bnan\b"),
    (["--duration", "-1"], r"\bduration\b.*-1"),
    (["--lag", "inf"], r"\blag\b.*\binf\b"),
]


@pytest.mark.parametrize("options, message", OPTION_CASES, ids=[c[0][0] for c in OPTION_CASES])
def test_bad_options_name_the_option(tmp_path, capsys, options, message):
    root = planar_log(tmp_path)
    code, out, err = run_cli(["smooth", root, "--out", tmp_path / "o", *options], capsys)
    assert code == exitcodes.BAD_INPUT and re.search(message, err), err
    assert not (tmp_path / "o" / "metrics.json").exists()


@pytest.mark.parametrize(
    "options, message",
    [
        (["--checkpoint", os.devnull + "/x"], r"--checkpoint \S+: must be a file in a writable"),
        (["--checkpoint", "."], r"--checkpoint \.: must be a file in a writable directory"),
        (["--resume", "no-such.json"], r"--resume no-such\.json: no such checkpoint file"),
        (["--checkpoint-every", "0"], r"--checkpoint-every must be >= 1, got 0"),
    ],
)
def test_bad_online_options_name_the_option(tmp_path, capsys, options, message):
    root = planar_log(tmp_path)
    code, _, err = run_cli(["online", root, "--out", tmp_path / "o", *options], capsys)
    assert code == exitcodes.BAD_INPUT and re.search(message, err), err
    assert not (tmp_path / "o" / "metrics.json").exists()


@pytest.mark.parametrize("verb", ["smooth", "online", "demo", "fuse-maps"])
@pytest.mark.parametrize("where", ["devnull", "file", "under-file"])
def test_out_is_checked_before_any_computation(tmp_path, capsys, verb, where):
    afile = tmp_path / "afile"
    afile.write_text("x")
    out = {"devnull": Path(os.devnull), "file": afile, "under-file": afile / "sub"}[where]
    args = {
        "smooth": [tmp_path / "nothing-read"],
        "online": [tmp_path / "nothing-read"],
        "demo": [],
        "fuse-maps": ["--simulate", "dual-robot-room"],
    }[verb]
    code, _, err = run_cli([verb, *args, "--out", out], capsys)
    assert code == exitcodes.BAD_INPUT, err
    assert re.match(rf"graphloc {verb}: error: --out {re.escape(str(out))}: ", err), err


@pytest.mark.parametrize(
    "exc, code, message",
    [
        (OSError(28, "No space left on device", "out/x.tum"), exitcodes.FAILED, "No space left"),
        (RuntimeError("[Open3D Error] HashMap"), exitcodes.FAILED, r"RuntimeError: \[Open3D"),
        (KeyboardInterrupt(), exitcodes.INTERRUPTED, "interrupted"),
        (FileNotFoundError("run/x.csv: missing"), exitcodes.BAD_INPUT, "run/x.csv: missing"),
    ],
)
def test_expected_failures_are_one_error_line_with_their_code(
    monkeypatch, capsys, exc, code, message
):
    from graphloc.commands import validate

    def fails(args):
        raise exc

    monkeypatch.setattr(validate, "run", fails)
    got, _, err = run_cli(["validate", "anything"], capsys)
    assert got == code and err.count("\n") == 1 and re.search(message, err), err


def test_exit_codes_are_distinct_and_documented():
    codes = [exitcodes.OK, exitcodes.FAILED, exitcodes.BAD_INPUT, exitcodes.INCOMPLETE]
    codes += [exitcodes.RUNS_FAILED, exitcodes.INCONSISTENT, exitcodes.INTERRUPTED]
    assert len(set(codes)) == len(codes) == len(exitcodes.CODES)
    doc = (Path(__file__).resolve().parents[2] / "docs" / "outputs.md").read_text()
    section = doc[doc.index("## Exit codes") :]
    for code in codes:
        assert re.search(rf"^\| {code} \|", section, re.M), code


# ---- point clouds (fuse-maps) --------------------------------------------------------------------
def scale_scans(folder: Path, factor: float) -> None:
    for p in folder.glob("*.ply"):
        pts = o3d.t.io.read_point_cloud(str(p)).point.positions.numpy().astype(float)
        write_cloud(p, pts * factor)


CLOUD_CASES = [
    ("millimetres", lambda c: scale_scans(c, 1000.0), r"median range \S+ is outside .*millim"),
    ("kilometres", lambda c: scale_scans(c, 1e-3), r"median range \S+ is outside .*kilom"),
    ("scaled-1e300", lambda c: scale_scans(c, 1e300), r"coordinates up to \S+, beyond \+-1e\+06"),
    (  # plausible on their own (median range ~250 m): caught beside the ground scans
        "centimetres",
        lambda c: scale_scans(c, 100.0),
        r"ceiling/00000\d\.ply and \S+/ground/00000\d\.ply: the ceiling scans' extent \(median "
        r"\S+ over 2 scans\) is \S+ x the ground scans' .* \(ratio near 100: centimetres\?\)",
    ),
    (
        "garbage-ply",
        lambda c: (c / "000001.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\n\x00\x01"),
        r"000001\.ply: not a PLY file, or its header has no end_header line",
    ),
    ("empty-file", lambda c: (c / "000001.ply").write_bytes(b""), r"000001\.ply: not a PLY file"),
    (  # Open3D warns "Read PLY failed" and returns the unread half uninitialised
        "truncated-ply",
        lambda c: (c / "000001.ply").write_bytes((c / "000001.ply").read_bytes()[:5000]),
        r"000001\.ply: truncated or corrupt: the header declares 400 rows \(9600 bytes of data\), "
        r"the file holds \d+ bytes of data",
    ),
    (
        "ten-identical-points",
        lambda c: write_cloud(c / "000001.ply", np.ones((10, 3))),
        r"000001\.ply: all 10 points lie within 1 mm of each other",
    ),
    (
        "all-nan",
        lambda c: write_cloud(c / "000001.ply", np.full((50, 3), np.nan)),
        r"000001\.ply: 0 finite points, at least 10 needed",
    ),
]


@pytest.mark.parametrize("name, breaks, message", CLOUD_CASES, ids=[c[0] for c in CLOUD_CASES])
def test_bad_scans_fail_before_registration_naming_the_file(
    tmp_path, capsys, name, breaks, message
):
    ground, ceiling = scan_dirs(tmp_path / "scans")
    breaks(ceiling)
    hint = "0 0 2.5 1 0 0 0"
    argv = ["fuse-maps", "--ground", ground, "--ceiling", ceiling, "--hint", hint]
    code, _, err = run_cli([*argv, "--out", tmp_path / "o"], capsys)
    assert code == exitcodes.BAD_INPUT and re.search(message, err), err
    assert str(ceiling) in err and not (tmp_path / "o" / "fusion_report.json").exists()


def test_two_robots_scans_in_different_units_are_an_error_before_registration(tmp_path, capsys):
    """The log reader's scans of two robots (the team graph registers them with each other):
    ceiling scans in centimetres beside ground scans in metres fail before KISS-ICP and the
    registration (Open3D's HashMap RuntimeError), naming a file of each robot and the unit."""
    run = tmp_path / "room"
    assert main(["simulate", "dual-robot-room", "--out", str(run), "--frames", "3"]) == 0
    capsys.readouterr()
    scale_scans(run / "scans" / "ceiling", 100.0)
    code, _, err = run_cli(["validate", run], capsys)
    assert code == exitcodes.BAD_INPUT, err
    assert re.search(
        r"scans/ceiling/00000\d\.ply and \S+/scans/ground/00000\d\.ply: the ceiling/lidar scans' "
        r"extent \(median \S+ over 3 scans\) is \S+ x the ground/lidar scans' .*\(ratio near 100: "
        r"centimetres\?\)",
        err,
    ), err
