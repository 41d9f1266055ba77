"""Helpers the test modules of every tests/ folder share (imported as `from helpers import ...`;
pyproject.toml puts tests/ on pytest's pythonpath): hypothesis settings and strategies of the
bad-input property tests, small valid inputs written on demand (a tiny MRCLAM directory and the
planar log made from it, a synthetic three-robot MRCLAM directory with counted bad lines, a tiny
two-robot log of every table, two robots' room scans, a Feng simulation with its odometry), and
edits of a log's manifest. Fixtures built on them are in conftest.py; the simulated bags are in
helpers_bags.py, the live route's comparisons in helpers_live.py."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from benchmarks.planar_factors import bearing_range_2d
from benchmarks.planar_factors import integrate_unicycle
from graphloc.records import columns
from graphloc.manifest import write_manifest

# ---- hypothesis ---------------------------------------------------------------------------------
# bounded for the default run; GRAPHLOC_FUZZ_EXAMPLES=2000 (random seeds) for a deeper search
EXAMPLES = int(os.environ.get("GRAPHLOC_FUZZ_EXAMPLES", "0"))
FAST = settings(
    max_examples=EXAMPLES or 40,
    deadline=None,
    derandomize=not EXAMPLES,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)

# what a mutated line of a text table is replaced with: any text, numbers and words the readers
# meet, or bytes that need not decode
REPLACEMENTS = st.one_of(
    st.text(max_size=30).filter(lambda s: "\n" not in s and "\r" not in s),
    st.lists(
        st.sampled_from(
            [
                "nan",
                "inf",
                "-inf",
                "1e308",
                "-1",
                "0",
                "1000.5",
                "999",
                "63",
                "3.2",
                "7",
                "x",
                "1e-320",
            ]
        ),
        min_size=0,
        max_size=5,
    ).map(" ".join),
    st.binary(min_size=1, max_size=6),
)

# what a leaf of a JSON document (a session file, a manifest) is replaced with
JSON_LEAVES = st.one_of(
    st.sampled_from(
        [
            0,
            1,
            -1,
            2,
            3,
            6,
            2**64 - 1,
            2**63,
            True,
            None,
            "x",
            "Huber",
            [],
            {},
            [1.0],
            [[1.0]],
            "PriorFactorPose3",
            "max_mixture",
            "pose3",
        ]
    ),
    st.floats(allow_nan=False, allow_infinity=False),
)


def json_paths(obj, prefix=()):
    """Every path (a tuple of keys and indices) to a node of the JSON document `obj`."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from json_paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from json_paths(v, prefix + (i,))
    if prefix:
        yield prefix


def set_json_leaf(doc, where, value) -> None:
    """Set the node of `doc` at the path `where` (one of json_paths') to `value`; nothing where
    an earlier edit changed the structure so that the path no longer leads anywhere."""
    obj = doc
    try:
        for key in where[:-1]:
            obj = obj[key]
        obj[where[-1]] = value
    except (KeyError, IndexError, TypeError):
        pass


# ---- a tiny MRCLAM run and the planar log made from it ------------------------------------------
T0 = 1000.0


def write_tiny_mrclam(root, seconds=(6.0, 6.0), offsets=(0.0, 0.0)) -> dict:
    """Two robots (subjects 1, 2) and two landmarks (6, 7): odometry and ground truth at 10 Hz,
    one measurement of each landmark every 0.5 s from T0 + 0.25 s to T0 + 5.75 s. Robot r's
    odometry spans [T0 + offsets[r], T0 + seconds[r]]. Returns {file name: list of lines}."""
    root.mkdir(parents=True, exist_ok=True)
    files = {
        "Barcodes.dat": ["# subject barcode", "1 5", "2 14", "6 63", "7 81"],
        "Landmark_Groundtruth.dat": [
            "# subject x y sx sy",
            "6 2.0 0.0 0.01 0.01",
            "7 0.0 2.0 0.01 0.02",
        ],
    }
    for r in range(2):
        t = T0 + np.arange(round(offsets[r] * 10), round(seconds[r] * 10) + 1) / 10
        files[f"Robot{r + 1}_Odometry.dat"] = ["# t v w"] + [f"{x:.3f} 0.1 0.05" for x in t]
        files[f"Robot{r + 1}_Groundtruth.dat"] = ["# t x y th"] + [
            f"{x:.3f} {0.1 * (x - T0):.4f} {r:.1f} {0.05 * (x - T0):.4f}" for x in t
        ]
        tm = T0 + 0.25 + 0.5 * np.arange(12)
        files[f"Robot{r + 1}_Measurement.dat"] = ["# t barcode range bearing"] + [
            f"{x:.3f} {code} {2.0 + 0.01 * k:.3f} 0.1"
            for k, x in enumerate(tm)
            for code in (63, 81)
        ]
    for name, lines in files.items():
        (root / name).write_text("\n".join(lines) + "\n")
    return files


def write_planar_log(tmp: Path) -> Path:
    """A valid graphloc log (two robots, odometry, range-bearing, ground truth, landmarks): the
    tiny MRCLAM run in tmp/mr through the MRCLAM reader, written to tmp/log."""
    from graphloc.datasets.mrclam import MRCLAM
    from graphloc.log_writer import write_planar_run

    write_tiny_mrclam(tmp / "mr")
    return write_planar_run(MRCLAM(tmp / "mr").load(), tmp / "log")


# ---- editing a log ------------------------------------------------------------------------------
def edit_manifest(root: Path, edit) -> None:
    """Apply `edit(dict)` to root/manifest.json (NaN and inf written as JSON's extensions)."""
    path = root / "manifest.json"
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))


def manifest(edit):
    """A breaker of a log: `edit(dict)` applied to its manifest."""
    return lambda root: edit_manifest(root, edit)


# ---- point clouds -------------------------------------------------------------------------------
def write_cloud(path: Path, pts: np.ndarray) -> None:
    import open3d as o3d

    path.parent.mkdir(parents=True, exist_ok=True)
    o3d.t.io.write_point_cloud(str(path), o3d.t.geometry.PointCloud(o3d.core.Tensor(pts)))


def scan_dirs(tmp: Path) -> tuple[Path, Path]:
    """Two robots' two scans each: points on the walls of a 6 x 4 x 3 m room around the
    sensor (median range ~2-3 m)."""
    rng = np.random.default_rng(0)
    for robot in ("ground", "ceiling"):
        for k in range(2):
            pts = rng.uniform([-3, -2, -1.5], [3, 2, 1.5], (400, 3))
            axis = rng.integers(0, 3, 400)
            rows = np.arange(400)
            pts[rows, axis] = np.sign(pts[rows, axis]) * np.array([3.0, 2.0, 1.5])[axis]
            write_cloud(tmp / robot / f"{k:06d}.ply", pts)
    return tmp / "ground", tmp / "ceiling"


# ---- a Feng simulation --------------------------------------------------------------------------
def simulate_feng(**kw):
    """FengProbabilisticScenario.simulate(FengProbabilisticConfig(**kw)) and its odometry as
    [None, Odometry, ...] (one per step, the first has none), with the config's noise."""
    from graphloc.datasets.feng import (
        FengProbabilisticConfig,
        FengProbabilisticScenario,
        odometry_covariance,
    )
    from graphloc.seams import Odometry

    cfg = FengProbabilisticConfig(**kw)
    run = FengProbabilisticScenario.simulate(cfg)
    odo = [None] + [
        Odometry(o, odometry_covariance(o, cfg.odometry_noise, cfg.odometry_rot_sigma))
        for o in run.odometry
    ]
    return run, odo


# ---- synthetic MRCLAM directory (tests/datasets/test_mrclam.py and the runs built on it) ---
HEADER = "# synthetic MRCLAM-format file\n# Time [s] ...\n"
LANDMARKS = {6: (3.0, 3.0), 7: (-3.0, 3.0), 8: (-3.0, -3.0), 9: (3.0, -3.0)}
BARCODES = {1: 5, 2: 14, 3: 41, 6: 63, 7: 81, 8: 7, 9: 70}
N_OUTLIERS = 5


def write_synthetic_mrclam(root: Path, duration=60.0, seed=0) -> dict:
    """Three robots driving smooth curves among four landmarks, odometry with a 5 % speed scale
    error and a turn-rate bias, measurements at 4 Hz. Plus bad lines: returns how many of each."""
    rng = np.random.default_rng(seed)
    root.mkdir(parents=True, exist_ok=True)
    t0 = 1000.0
    bad = {"parse": 0, "non_finite": 0, "time_backwards": 0, "field_count": 0, "unknown_barcode": 0}
    (root / "Barcodes.dat").write_text(HEADER + "".join(f"{s}\t{b}\n" for s, b in BARCODES.items()))
    (root / "Landmark_Groundtruth.dat").write_text(
        HEADER + "".join(f"{i}\t{x}\t{y}\t0.0001\t0.0001\n" for i, (x, y) in LANDMARKS.items())
    )
    t_odo = t0 + np.arange(0, duration, 0.02)
    starts = [(0.0, -1.0, 0.3), (-1.0, 1.0, -0.5), (1.0, 1.0, 2.5)]
    gts = []
    for r, start in enumerate(starts):
        v = 0.15 + 0.05 * np.sin(0.1 * (t_odo - t0) + r)
        w = 0.25 * np.sin(0.07 * (t_odo - t0) + 2 * r)
        gt = integrate_unicycle(t_odo, v, w, t_odo, start=start).poses
        gts.append(gt)
        odo = np.column_stack(
            [t_odo, 1.05 * v + rng.normal(0, 0.005, v.size), w + 0.02 + rng.normal(0, 0.02, w.size)]
        )
        lines = [f"{t:.3f}\t{a:.4f}\t{b:.4f}\n" for t, a, b in odo]
        lines.insert(100, "1000.5 0.1\n")
        bad["field_count"] += 1
        lines.insert(200, "1001.0 abc 0.1\n")
        bad["parse"] += 1
        lines.insert(300, f"{t_odo[299]:.3f} nan 0.1\n")
        bad["non_finite"] += 1
        lines.insert(400, f"{t_odo[10]:.3f} 0.1 0.1\n")  # time goes backwards
        bad["time_backwards"] += 1
        (root / f"Robot{r + 1}_Odometry.dat").write_text(HEADER + "".join(lines))
        (root / f"Robot{r + 1}_Groundtruth.dat").write_text(
            HEADER
            + "".join(f"{t:.3f}\t{x:.6f}\t{y:.6f}\t{th:.6f}\n" for t, (x, y, th) in zip(t_odo, gt))
        )
    t_meas = t0 + 1.0 + np.arange(0, duration - 2.0, 0.25)
    idx = np.searchsorted(t_odo, t_meas)
    for r in range(3):
        rows = []
        pose = gts[r][idx]
        targets = [(BARCODES[i], np.tile(xy, (idx.size, 1))) for i, xy in LANDMARKS.items()]
        targets += [(BARCODES[j + 1], gts[j][idx, :2]) for j in range(3) if j != r]
        for code, pts in targets:
            b, d = bearing_range_2d(pose, pts)
            b = b + rng.normal(0, 0.01, b.size)
            d = d + rng.normal(0, 0.03, d.size)
            rows += [(t, code, dd, bb) for t, dd, bb in zip(t_meas, d, b)]
        rows.sort(key=lambda row: row[0])
        if (
            r == 0
        ):  # gross range outliers on landmark measurements (what the robust kernel must mute)
            for i in [i for i, row in enumerate(rows) if row[1] == BARCODES[6]][
                10 : 10 + N_OUTLIERS
            ]:
                rows[i] = (rows[i][0], rows[i][1], rows[i][2] + 3.0, rows[i][3])
        lines = [f"{t:.3f}\t{c}\t{d:.3f}\t{b:.3f}\n" for t, c, d, b in rows]
        lines.insert(50, f"{rows[50][0]:.3f}\t99\t2.0\t0.1\n")  # misread barcode
        bad["unknown_barcode"] += 1
        lines.insert(60, f"{rows[60][0]:.3f}\t63\tinf\t0.1\n")
        bad["non_finite"] += 1
        (root / f"Robot{r + 1}_Measurement.dat").write_text(HEADER + "".join(lines))
    return bad


# ---- the tiny two-robot log of every table (tests/core/test_io.py) -----------------------
def _csv(path: Path, table: str, rows: list[str]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(",".join(columns(table)) + "\n" + "".join(r + "\n" for r in rows))


def make_log(root: Path, odo_a=None, rb_a=None) -> Path:
    write_manifest(
        {
            "name": "tiny",
            "start_time": 0.0,
            "robots": [
                {
                    "name": "ground",
                    "kind": "ground",
                    "initial_pose": [0, 0, 0],
                    "sensors": [
                        {"name": "wheels", "type": "odometry"},
                        {
                            "name": "cam",
                            "type": "range_bearing",
                            "extrinsics": [0.1, 0.0, 1.5707963267948966],
                        },
                        {
                            "name": "ceilcam",
                            "type": "camera",
                            "extrinsics": {"xyz": [0, 0, 0.2], "rpy": [0, 0, 0]},
                        },
                        {"name": "lidar", "type": "scanner"},
                    ],
                    "tables": {
                        "odometry": "ground/odometry.csv",
                        "range_bearing": "ground/range_bearing.csv",
                        "markers": "ground/markers.csv",
                        "candidates": "ground/candidates.csv",
                        "scans": "ground/scans.csv",
                        "groundtruth": "ground/groundtruth.csv",
                    },
                },
                {
                    "name": "climber",
                    "kind": "wall",
                    "initial_pose": [1, 0, 0],
                    "sensors": [
                        {"name": "wheels", "type": "odometry"},
                        {"name": "eye", "type": "bearing"},
                    ],
                    "tables": {
                        "odometry": "climber/odometry.csv",
                        "bearing": "climber/bearing.csv",
                    },
                },
            ],
            "landmarks": {"file": "landmarks.csv"},
        },
        root,
    )
    (root / "landmarks.csv").write_text(
        "id,x,y,z,sigma_x,sigma_y,sigma_z\n3,2.0,0.0,0,0.01,0.01,0\n"
    )
    _csv(
        root / "ground/odometry.csv",
        "odometry",
        odo_a or ["0.0,wheels,0.1,0.0", "0.5,wheels,0.1,0.0", "1.0,wheels,0.1,0.0"],
    )
    _csv(
        root / "ground/range_bearing.csv",
        "range_bearing",
        rb_a or ["0.25,cam,landmark:3,1.0,0.0", "0.75,cam,climber,2.0,-1.0"],
    )
    _csv(root / "ground/markers.csv", "markers", ["0.3,ceilcam,climber,0,320.5,240.25"])
    _csv(
        root / "ground/candidates.csv",
        "candidates",
        ["0.3,ceilcam,climber,0,0.9,1,0,0,0,0.5,0,1", "0.3,ceilcam,climber,1,0.1,0,1,0,0,0.4,0,1"],
    )
    _csv(root / "ground/scans.csv", "scans", ["0.6,lidar,scans/000001.pcd"])
    _csv(root / "ground/groundtruth.csv", "groundtruth", ["0.0,0,0,0", "1.0,0.1,0,0"])
    _csv(root / "climber/odometry.csv", "odometry", ["0.1,wheels,0.0,0.0", "0.9,wheels,0.0,0.1"])
    _csv(root / "climber/bearing.csv", "bearing", ["0.2,eye,ground,0,1,0"])
    return root
