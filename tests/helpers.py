"""Helpers the test modules share (imported as `from helpers import ...`; tests/ is on sys.path
as pytest's rootdir-relative test folder): hypothesis settings and strategies of the bad-input
property tests, small valid inputs written on demand (a tiny MRCLAM directory and the planar log
made from it, two robots' room scans, a Feng simulation with its odometry), and edits of a
log's manifest. Fixtures built on them are in conftest.py."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

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
