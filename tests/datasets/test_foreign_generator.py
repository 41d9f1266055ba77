"""The outside user's log generator (tests/foreign/team_generator.py, issue 48) checked from the
files it writes: headers as docs/log_format.md lists them, times, unit bearings, markers in the
image, ground truth for every robot, the noise it states, the corruptions, determinism."""

from __future__ import annotations

import csv
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "foreign"))

import score  # noqa: E402
import team_generator as gen  # noqa: E402

DOC = Path(__file__).resolve().parents[2] / "docs" / "log_format.md"
SHORT = {"ceiling-markers": 30.0, "wall-bearings": 30.0, "mixed-team": 30.0}


def doc_headers() -> dict[str, list[str]]:
    """Table name -> columns, parsed from the "Tables" section of docs/log_format.md."""
    text = DOC.read_text()
    section = text.split("## Tables", 1)[1].split("\n## ", 1)[0]
    out = {}
    for line in section.splitlines():
        m = re.match(r"^\| `(\w+)` \| [^|]+ \| `([a-z0-9_,]+)`", line)
        if m:
            out[m.group(1)] = m.group(2).split(",")
    return out


def read_csv(path: Path) -> tuple[list[str], list[dict]]:
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        return list(reader.fieldnames or []), list(reader)


def tables_of(run: Path):
    """(robot entry, table name, path) of every table of the manifest."""
    manifest = json.loads((run / "manifest.json").read_text())
    for robot in manifest["robots"]:
        for table, rel in robot["tables"].items():
            yield robot, table, run / rel


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("foreign")
    return {
        layout: gen.generate(
            root / layout, gen.GeneratorConfig(layout=layout, seed=3, duration_s=SHORT[layout])
        )
        for layout in gen.LAYOUTS
    }


def test_the_generator_writes_the_columns_the_doc_lists(runs):
    doc = doc_headers()
    assert {"odometry", "relative_pose3", "markers", "bearing", "groundtruth"} <= set(doc)
    for table, columns in gen.HEADERS.items():
        assert doc[table] == columns, table
    seen = set()
    for run in runs.values():
        for _, table, path in tables_of(run):
            seen.add(table)
            if path.suffix == ".tum":
                first = path.read_text().splitlines()[0].split()
                assert len(first) == 8, path
                continue
            header, _ = read_csv(path)
            assert header == doc[table], path
    assert set(gen.HEADERS) <= seen  # every table kind is written by some layout


def test_rows_are_in_time_order_and_sensors_have_the_table_type(runs):
    for run in runs.values():
        for robot, table, path in tables_of(run):
            if path.suffix == ".tum":
                times = [float(line.split()[0]) for line in path.read_text().splitlines()]
            else:
                _, rows = read_csv(path)
                times = [float(r["time"]) for r in rows]
                types = {s["name"]: s["type"] for s in robot["sensors"]}
                for r in rows if table != "groundtruth" else []:
                    assert types[r["sensor"]] == gen.SENSOR_TYPE[table], (path, r)
            assert times, path
            assert all(b >= a for a, b in zip(times, times[1:])), path


def test_targets_are_robots_or_landmarks_and_never_the_owner(runs):
    for run in runs.values():
        manifest = json.loads((run / "manifest.json").read_text())
        names = {r["name"] for r in manifest["robots"]}
        landmarks = set()
        if (run / "landmarks.csv").exists():
            landmarks = {f"landmark:{r['id']}" for r in read_csv(run / "landmarks.csv")[1]}
        for robot, _table, path in tables_of(run):
            if path.suffix == ".tum":
                continue
            header, rows = read_csv(path)
            if "target" in header:
                targets = {r["target"] for r in rows}
                assert targets <= names | landmarks, path
                assert robot["name"] not in targets, path


def test_bearings_are_unit_vectors(runs):
    count = 0
    for run in runs.values():
        for _, table, path in tables_of(run):
            if table == "bearing":
                for r in read_csv(path)[1]:
                    n = math.sqrt(sum(float(r[c]) ** 2 for c in "xyz"))
                    assert abs(n - 1.0) < 1e-9, (path, r)
                    count += 1
    assert count > 100


def test_markers_are_inside_the_image_in_their_layout_and_leave_it(runs):
    manifest = json.loads((runs["ceiling-markers"] / "manifest.json").read_text())
    robots = {r["name"]: r for r in manifest["robots"]}
    climber = robots["climber"]
    params = next(s for s in climber["sensors"] if s["type"] == "camera")["params"]
    _, rows = read_csv(runs["ceiling-markers"] / climber["tables"]["markers"])
    sets: dict = {}
    for r in rows:
        u, v = float(r["u"]), float(r["v"])
        assert 0.0 <= u <= params["width"] - 1 and 0.0 <= v <= params["height"] - 1, r
        layout = robots[r["target"]]["markers"]
        assert 0 <= int(r["marker"]) < len(layout)
        sets.setdefault((r["time"], r["target"]), []).append(int(r["marker"]))
    for markers in sets.values():
        assert len(set(markers)) == len(markers)  # distinct markers, each once per frame
    sizes = {len(robots[t]["markers"]) for _, t in sets}
    assert sizes == {3, 4}  # 3- and 4-marker layouts are both seen
    partial = [k for k, m in sets.items() if len(m) < len(robots[k[1]]["markers"])]
    assert partial, "no marker ever leaves the image"
    static = {n for n, r in robots.items() if r.get("static")}
    moving = {n for n, r in robots.items() if "odometry" in r["tables"]}
    targets = {t for _, t in sets}
    assert static & targets and moving & targets


def test_every_robot_has_ground_truth_over_the_run(runs):
    for layout, run in runs.items():
        truth = score.read_truth(run)
        manifest = json.loads((run / "manifest.json").read_text())
        assert {r["name"] for r in manifest["robots"]} == set(truth)
        for name, tr in truth.items():
            assert tr["t"][0] == 0.0 and tr["t"][-1] >= SHORT[layout] - 1e-6, (layout, name)
            if tr["static"]:
                assert np.ptp(tr["xyz"], axis=0).max() == 0.0


def test_the_surfaces_are_sloped_ceilings_and_vertical_walls(runs):
    seen = set()
    for run in runs.values():
        manifest = json.loads((run / "manifest.json").read_text())
        truth = score.read_truth(run)
        for robot in manifest["robots"]:
            surface = robot.get("surface")
            if surface is None:
                continue
            normal = np.asarray(surface["normal"])
            assert abs(np.linalg.norm(normal) - 1.0) < 1e-9
            tilt = math.degrees(math.acos(abs(normal[2])))
            if robot["kind"] == "ceiling":
                assert 10.0 <= tilt <= 20.0 and normal[2] < 0
            else:
                assert robot["kind"] == "wall" and abs(normal[2]) < 1e-12
            seen.add(robot["kind"])
            # the body origin stays on the plane, its z axis along the normal
            tr = truth[robot["name"]]
            dist = (tr["xyz"] - np.asarray(surface["point"])) @ normal
            assert np.abs(dist).max() < 1e-6
            z_axes = Rotation.from_quat(tr["quat"]).apply([0.0, 0.0, 1.0])
            assert np.allclose(z_axes, normal, atol=1e-6)
    assert seen == {"ceiling", "wall"}


def _sensor_pose(robot: dict, sensor: str) -> np.ndarray:
    entry = next(s for s in robot["sensors"] if s["name"] == sensor)
    ext = entry["extrinsics"]
    return gen.transform(gen.rpy_matrix(ext["rpy"]), ext["xyz"])


def test_the_stated_noise_is_the_noise_added(runs):
    """Residuals of the rows against the ground truth have the manifest's / rows' sigmas."""
    run = runs["wall-bearings"]
    manifest = json.loads((run / "manifest.json").read_text())
    robots = {r["name"]: r for r in manifest["robots"]}
    truth = score.read_truth(run)
    # mutual bearings of the static ground robots (no jitter, no bias): angular residuals
    angles, sigmas = [], []
    for name in ("g1", "g2", "g3"):
        robot = robots[name]
        pose = gen.transform(Rotation.from_quat(truth[name]["quat"][0]).as_matrix(),
                             truth[name]["xyz"][0])  # fmt: skip
        for r in read_csv(run / robot["tables"]["bearing"])[1]:
            world_t_sensor = pose @ _sensor_pose(robot, r["sensor"])
            d = world_t_sensor[:3, :3].T @ (truth[r["target"]]["xyz"][0] - world_t_sensor[:3, 3])
            d /= np.linalg.norm(d)
            meas = np.array([float(r[c]) for c in "xyz"])
            angles.append(math.acos(np.clip(meas @ d, -1.0, 1.0)))
        sigma = next(s for s in robot["sensors"] if s["name"] == "omni")["params"]
        sigmas.append(sigma["bearing_sigma"])
    # two tangent components of sigma each: E[angle^2] = 2 sigma^2
    rms = math.sqrt(np.mean(np.square(angles)) / 2.0)
    assert 0.8 * sigmas[0] < rms < 1.2 * sigmas[0], (rms, sigmas[0])
    # relative_pose3 of the wall robot: whitened residuals in each tangent component
    waller = robots["waller"]
    tr = truth["waller"]
    whitened = []
    for r in read_csv(run / waller["tables"]["relative_pose3"])[1]:
        poses = []
        for t in (float(r["time0"]), float(r["time"])):
            i = int(np.argmin(np.abs(tr["t"] - t)))
            assert abs(tr["t"][i] - t) < 1e-9
            poses.append(gen.transform(Rotation.from_quat(tr["quat"][i]).as_matrix(), tr["xyz"][i]))
        true_delta = gen.inverse(poses[0]) @ poses[1]
        q = [float(r[c]) for c in ("qx", "qy", "qz", "qw")]
        t_meas = [float(r["tx"]), float(r["ty"]), float(r["tz"])]
        meas = gen.transform(Rotation.from_quat(q).as_matrix(), t_meas)
        err = gen.inverse(true_delta) @ meas
        xi = np.r_[Rotation.from_matrix(err[:3, :3]).as_rotvec(), err[:3, 3]]
        sig = np.array(
            [
                float(r[c])
                for c in ("sigma_rx", "sigma_ry", "sigma_rz", "sigma_tx", "sigma_ty", "sigma_tz")
            ]
        )
        whitened.append(xi / sig)
    std = np.std(whitened, axis=0)
    assert np.all((std > 0.85) & (std < 1.15)), std


def test_wheel_odometry_carries_a_small_systematic_bias(runs):
    run = runs["ceiling-markers"]
    manifest = json.loads((run / "manifest.json").read_text())
    truth = score.read_truth(run)
    ratios = []
    for robot in manifest["robots"]:
        if "odometry" not in robot["tables"]:
            continue
        _, rows = read_csv(run / robot["tables"]["odometry"])
        t = np.array([float(r["time"]) for r in rows])
        v = np.array([float(r["v"]) for r in rows])
        travelled = float(np.sum(v[:-1] * np.diff(t)))
        tr = truth[robot["name"]]
        true_path = float(np.sum(np.linalg.norm(np.diff(tr["xyz"], axis=0), axis=1)))
        ratios.append(travelled / true_path)
    assert len(ratios) == 3
    assert all(0.01 < abs(r - 1.0) < 0.06 for r in ratios), ratios


def test_wall_bearings_is_bearing_heavy():
    log = gen.build(gen.GeneratorConfig(layout="wall-bearings", seed=0))
    poses = len(log.tables["waller/relative_pose3.csv"][1]) + 1
    bearings = sum(len(rows) for table, rows in log.tables.values() if table == "bearing")
    assert 900 <= poses <= 1100 and 1200 <= bearings <= 1400, (poses, bearings)
    robots = {r.name: r for r in log.robots}
    assert [n for n, r in robots.items() if r.static and r.initial_pose] == ["g1"]
    assert len(log.tables["g1/range.csv"][1]) == 1


def _files(run: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(run)): p.read_bytes()
        for p in sorted(run.rglob("*"))
        if p.is_file() and p.name != "generator.json"
    }


def test_a_seed_gives_the_same_run_and_another_seed_another(tmp_path):
    config = gen.GeneratorConfig(layout="mixed-team", seed=5, duration_s=20.0)
    a = _files(gen.generate(tmp_path / "a", config))
    b = _files(gen.generate(tmp_path / "b", config))
    c = _files(gen.generate(tmp_path / "c", gen.GeneratorConfig("mixed-team", 6, duration_s=20)))
    assert a == b
    assert a.keys() == c.keys() and a != c


@pytest.mark.parametrize("kind", gen.CORRUPTIONS)
def test_each_corruption_changes_what_it_says_and_nothing_else(tmp_path, kind):
    layout = "wall-bearings" if kind == "odometry-x2" else "ceiling-markers"
    clean = gen.generate(tmp_path / "clean", gen.GeneratorConfig(layout, 1, duration_s=20.0))
    bad = gen.generate(tmp_path / "bad", gen.GeneratorConfig(layout, 1, kind, duration_s=20.0))
    a, b = _files(clean), _files(bad)
    said = json.loads((bad / "generator.json").read_text())["corruption"]
    ma = json.loads(a["manifest.json"])
    mb = json.loads(b["manifest.json"])
    assert mb.pop("name") == ma.pop("name") + f"-{kind}"  # the run's name says it, nothing else
    changed = {k for k in a if a[k] != b[k] and k != "manifest.json"} | (
        {"manifest.json"} if ma != mb else set()
    )
    if kind == "swap-uv":
        assert changed == {"climber/markers.csv"}
        ra, rb = (
            read_csv(clean / "climber/markers.csv")[1],
            read_csv(bad / "climber/markers.csv")[1],
        )
        assert all(x["u"] == y["v"] and x["v"] == y["u"] for x, y in zip(ra, rb))
    elif kind == "wrong-intrinsics":
        assert changed == {"manifest.json"}
        pa, pb = ma["robots"][0]["sensors"][1]["params"], mb["robots"][0]["sensors"][1]["params"]
        assert pb["fx"] == pytest.approx(1.2 * pa["fx"]) and pb["fy"] == pytest.approx(
            1.2 * pa["fy"]
        )
        assert {k: v for k, v in pa.items() if k not in ("fx", "fy")} == {
            k: v for k, v in pb.items() if k not in ("fx", "fy")
        }
    elif kind in ("wrong-layout", "wrong-layout-scale"):
        assert changed == {"manifest.json"}
        la = {r["name"]: np.array(r.get("markers", [])) for r in ma["robots"]}
        lb = {r["name"]: np.array(r.get("markers", [])) for r in mb["robots"]}
        diff = [n for n in la if not np.array_equal(la[n], lb[n])]
        assert diff == [said["target"]]
        old, new = la[diff[0]], lb[diff[0]]
        if kind == "wrong-layout":
            assert sorted(map(tuple, old)) == sorted(map(tuple, new))
            assert all(not np.array_equal(p, q) for p, q in zip(old, new))
        else:
            assert np.allclose(new, 1.3 * old, atol=1e-6)
    elif kind == "odometry-x2":
        assert changed == {said["table"]}
        ra, rb = read_csv(clean / said["table"])[1], read_csv(bad / said["table"])[1]
        for x, y in zip(ra, rb):
            ta = np.array([float(x[c]) for c in ("tx", "ty", "tz")])
            tb = np.array([float(y[c]) for c in ("tx", "ty", "tz")])
            assert np.allclose(tb, 2.0 * ta, atol=1e-9)
    elif kind == "target-typo":
        assert changed == {said["table"]}
        names = {r["name"] for r in ma["robots"]}
        targets = {r["target"] for r in read_csv(bad / said["table"])[1]}
        assert targets and not targets & names
        assert {k for k in said["typos"]} <= names


def test_the_wheel_odometry_corruption_doubles_v_and_omega(tmp_path):
    clean = gen.generate(tmp_path / "c", gen.GeneratorConfig("ceiling-markers", 2, duration_s=15))
    bad = gen.generate(
        tmp_path / "b", gen.GeneratorConfig("ceiling-markers", 2, "odometry-x2", duration_s=15)
    )
    said = json.loads((bad / "generator.json").read_text())["corruption"]
    assert said["table"].endswith("/odometry.csv")
    for x, y in zip(read_csv(clean / said["table"])[1], read_csv(bad / said["table"])[1]):
        assert float(y["v"]) == pytest.approx(2.0 * float(x["v"]), abs=1e-9)
        assert float(y["omega"]) == pytest.approx(2.0 * float(x["omega"]), abs=1e-9)


def test_the_cli_writes_a_run_and_refuses_a_used_folder(tmp_path, capsys):
    out = tmp_path / "run"
    args = ["--out", str(out), "--seed", "1", "--layout", "wall-bearings", "--duration", "12"]
    assert gen.main(args) == 0
    assert (out / "manifest.json").exists()
    assert gen.main(args) == 2
    assert "not empty" in capsys.readouterr().err
    with pytest.raises(ValueError, match="layout"):
        gen.GeneratorConfig(layout="nope").check()


def test_score_measures_world_frame_errors_of_tum_estimates(runs, tmp_path):
    """score.py on estimates made from the truth: 0 error; shifted by 1 m: 1 m; missing:
    unplaced; decided sets off by 0.8 m are counted wrong."""
    run = runs["ceiling-markers"]
    truth = score.read_truth(run)
    for name, tr in truth.items():
        shift = np.array([0.6, 0.8, 0.0]) if name == "rover3" else np.zeros(3)
        if name == "rover4":
            continue  # left out: unplaced
        with open(tmp_path / f"{name}_batch.tum", "w") as fh:
            for t, p, q in zip(tr["t"], tr["xyz"] + shift, tr["quat"]):
                fh.write(" ".join(f"{v:.9f}" for v in (t, *p, *q)) + "\n")
    tr = truth["climber"]
    with open(tmp_path / "decisions.csv", "w") as fh:
        fh.write("time,robot,target,candidates,committed,probability,genuine,correct,"
                 "x,y,z,qx,qy,qz,qw\n")  # fmt: skip
        for i, off in ((10, 0.0), (20, 0.8)):
            x, y, z = tr["xyz"][i] + [off, 0, 0]
            fh.write(f"{tr['t'][i]},climber,anchor4,2,0,0.9,0,1,{x},{y},{z},0,0,0,1\n")
    result = score.score(run, tmp_path, "batch")
    assert result["robots"]["climber"]["max_m"] < 1e-6
    assert result["robots"]["rover3"]["final_m"] == pytest.approx(1.0, abs=1e-6)
    assert result["unplaced"] == ["rover4"]
    assert result["decisions"]["decided"] == 2
    assert result["decisions"]["wrong_by_truth"] == 1
    assert result["decisions"]["wrong_by_graphloc"] == 0
