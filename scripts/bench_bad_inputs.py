"""Time and memory of two bad inputs of issue 47 against a clean peer measured in the same run,
written as JSON (no timed unit test: docs/architecture.md, "Rules of the house").

    .venv/bin/python scripts/bench_bad_inputs.py [--rows 1000000] [--points 5000000]
        [--out out/bench_bad_inputs.json]

- `markers`: `graphloc validate` of the simulated feng-probabilistic log with `--rows` copies of
  its first markers row inserted (one image with one marker seen `rows` + 1 times: every row a
  counted `duplicate_marker` skip); peer: the same log as simulated.
- `dense_scan`: `graphloc fuse-maps --ground G --ceiling C --hint ...` on one synthetic room
  scan per robot of `--points` points (thinned on read to graphloc.mapping.io.POINT_BUDGET);
  peer: the same scans cut to the budget beforehand.

Each verb runs in its own process; wall time, CPU time (user + system) and peak resident memory
of that process are measured (`os.wait4`), with the ratios case / peer.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

GRAPHLOC = [sys.executable, "-m", "graphloc"]


def measure(argv: list[str]) -> dict:
    """Run `argv`; its wall time [s], CPU time [s], peak RSS [MB] and exit code."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    return {
        "wall_s": round(wall, 3),
        "cpu_s": round(usage.ru_utime + usage.ru_stime, 3),
        "peak_rss_mb": round(usage.ru_maxrss / 1024, 1),
        "exit_code": os.waitstatus_to_exitcode(status),
        "stderr_tail": err[-300:],
    }


def ratios(case: dict, peer: dict) -> dict:
    return {k: round(case[k] / max(peer[k], 1e-9), 3) for k in ("wall_s", "cpu_s", "peak_rss_mb")}


def markers_case(tmp: Path, rows: int) -> dict:
    log = tmp / "feng"
    subprocess.run(
        [*GRAPHLOC, "simulate", "feng-probabilistic", "--out", str(log), "-q"], check=True
    )
    peer = measure([*GRAPHLOC, "validate", str(log)])
    path = log / "climber" / "markers.csv"
    lines = path.read_text().splitlines()
    with open(path, "w") as fh:
        fh.write(lines[0] + "\n")
        fh.write((lines[1] + "\n") * (rows + 1))
        fh.write("\n".join(lines[2:]) + "\n")
    case = measure([*GRAPHLOC, "validate", str(log)])
    return {"rows_added": rows, "case": case, "peer": peer, "case_over_peer": ratios(case, peer)}


def room_points(rng, n: int) -> np.ndarray:
    """n points on a 6 x 4 x 3 m room's floor, ceiling, walls, a table top and a cabinet."""
    faces = [  # (weight, fixed axis, value, (lo, hi) of the other two axes)
        (24, 2, 0.0, ((-3, 3), (-2, 2))),
        (24, 2, 3.0, ((-3, 3), (-2, 2))),
        (12, 0, -3.0, ((-2, 2), (0, 3))),
        (12, 0, 3.0, ((-2, 2), (0, 3))),
        (18, 1, -2.0, ((-3, 3), (0, 3))),
        (18, 1, 2.0, ((-3, 3), (0, 3))),
        (6, 2, 0.8, ((-2, -1), (0.5, 1.3))),
        (6, 0, 1.5, ((-1.5, -0.5), (0, 1.8))),
    ]
    w = np.array([f[0] for f in faces], float)
    which = rng.choice(len(faces), n, p=w / w.sum())
    pts = np.empty((n, 3))
    for k, (_, axis, value, spans) in enumerate(faces):
        sel = which == k
        others = [a for a in range(3) if a != axis]
        pts[sel, axis] = value
        for a, (lo, hi) in zip(others, spans):
            pts[sel, a] = rng.uniform(lo, hi, sel.sum())
    return pts + rng.normal(0.0, 0.003, pts.shape)


def dense_case(tmp: Path, points: int) -> dict:
    import open3d as o3d
    from scipy.spatial.transform import Rotation

    from graphloc.mapping.io import POINT_BUDGET

    rng = np.random.default_rng(0)
    ground, ceiling = np.eye(4), np.eye(4)
    ground[:3, 3] = [0.0, 0.0, 0.3]
    ceiling[:3, :3] = Rotation.from_euler("x", 180, degrees=True).as_matrix()
    ceiling[:3, 3] = [0.6, 0.3, 2.9]
    T = np.linalg.inv(ground) @ ceiling
    hint = " ".join(f"{v:.4f}" for v in [*T[:3, 3], *Rotation.from_matrix(T[:3, :3]).as_quat()])
    for name, pose in (("ground", ground), ("ceiling", ceiling)):
        local = (room_points(rng, points) - pose[:3, 3]) @ pose[:3, :3]
        for label, pts in (("case", local), ("peer", local[:POINT_BUDGET])):
            folder = tmp / label / name
            folder.mkdir(parents=True)
            cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(pts.astype(np.float32)))
            o3d.t.io.write_point_cloud(str(folder / "000000.ply"), cloud)
    out = {}
    for label in ("peer", "case"):
        argv = [*GRAPHLOC, "fuse-maps", "--ground", str(tmp / label / "ground")]
        argv += ["--ceiling", str(tmp / label / "ceiling"), "--hint", hint]
        out[label] = measure([*argv, "--out", str(tmp / label / "out")])
    return {
        "points": points,
        "point_budget": POINT_BUDGET,
        **out,
        "case_over_peer": ratios(out["case"], out["peer"]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=int, default=1_000_000)
    parser.add_argument("--points", type=int, default=5_000_000)
    parser.add_argument("--out", type=Path, default=Path("out/bench_bad_inputs.json"))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        report = {
            "markers": markers_case(Path(tmp) / "m", args.rows),
            "dense_scan": dense_case(Path(tmp) / "d", args.points),
        }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1) + "\n")
    print(json.dumps({k: v["case_over_peer"] for k, v in report.items()}))


if __name__ == "__main__":
    main()
