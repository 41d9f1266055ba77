"""Score graphloc's outputs on a generated run against the generator's ground truth.

Reads only files: the run's ``manifest.json`` and ground-truth tables (``groundtruth.csv``
``time,x,y,theta``, planar at z = 0; ``groundtruth.tum``), and graphloc's output folder
(``<robot>_<mode>.tum``, ``decisions.csv``, ``metrics.json``, as docs/outputs.md describes
them). No graphloc import.

Errors are positions in the world frame with no alignment: the generated logs anchor the world
through ``initial_pose`` (``start_time`` 0), so an estimate is right only where it is.

- per robot: the position error of every estimated pose against the truth interpolated at its
  time (linear in position; a static robot's truth is its one pose): ``final_m`` (last pose),
  ``max_m``, ``rmse_m``, ``n``, and ``final_rot_deg`` (rotation angle between the last
  estimated orientation and the truth's nearest in time); a robot of the manifest without an
  estimate file is ``unplaced``.
- decisions: every decided set of ``decisions.csv`` (``committed`` >= 0) is judged by the truth,
  independently of graphloc's own ``correct`` column: wrong when the decided candidate's body
  position is more than ``decision_bar_m`` (0.5 m) from the observer's true position at that
  time; ``pnp_reference`` sets that beside PnP on all of the set's pixels at the true target
  pose (single frames of these layouts are 0.1-0.2 m uncertain, so the bar is not tighter).

CLI: ``python tests/foreign/score.py RUN OUT [--mode batch|online]`` prints JSON.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation


def read_tum(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(times, positions (N, 3), quaternions xyzw (N, 4))`` of a TUM file."""
    rows = []
    for line in Path(path).read_text().splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        rows.append([float(v) for v in line.replace(",", " ").split()])
    if not rows:
        return np.zeros(0), np.zeros((0, 3)), np.zeros((0, 4))
    arr = np.asarray(rows, float)
    return arr[:, 0], arr[:, 1:4], arr[:, 4:8]


def read_planar_truth(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    with open(path, newline="") as fh:
        rows = [r for r in csv.DictReader(fh)]
    t = np.array([float(r["time"]) for r in rows])
    xyz = np.array([[float(r["x"]), float(r["y"]), 0.0] for r in rows])
    yaw = np.array([float(r["theta"]) for r in rows])
    quat = Rotation.from_euler("z", yaw[:, None]).as_quat()
    return t, xyz, quat


def read_truth(run_dir: Path) -> dict[str, dict]:
    """Robot name -> ``{"t", "xyz", "quat", "static"}`` from the manifest's groundtruth tables."""
    manifest = json.loads((run_dir / "manifest.json").read_text())
    out = {}
    for robot in manifest["robots"]:
        path = robot.get("tables", {}).get("groundtruth")
        if path is None:
            continue
        path = run_dir / path
        t, xyz, quat = read_tum(path) if path.suffix == ".tum" else read_planar_truth(path)
        out[robot["name"]] = {"t": t, "xyz": xyz, "quat": quat, "static": robot.get("static")}
    return out


def truth_position(truth: dict, times: np.ndarray) -> np.ndarray:
    if truth["static"] or len(truth["t"]) == 1:
        return np.repeat(truth["xyz"][:1], len(times), axis=0)
    return np.column_stack([np.interp(times, truth["t"], truth["xyz"][:, i]) for i in range(3)])


def truth_quat(truth: dict, time: float) -> np.ndarray:
    i = int(np.argmin(np.abs(truth["t"] - time)))
    return truth["quat"][i]


def score_robot(truth: dict, est_path: Path) -> dict:
    t, xyz, quat = read_tum(est_path)
    if len(t) == 0:
        return {"unplaced": True, "n": 0}
    err = np.linalg.norm(xyz - truth_position(truth, t), axis=1)
    q_err = Rotation.from_quat(quat[-1]).inv() * Rotation.from_quat(truth_quat(truth, t[-1]))
    return {
        "n": int(len(t)),
        "final_m": round(float(err[-1]), 4),
        "max_m": round(float(err.max()), 4),
        "rmse_m": round(float(math.sqrt(np.mean(err**2))), 4),
        "final_rot_deg": round(float(np.degrees(q_err.magnitude())), 3),
    }


def score_decisions(truth: dict[str, dict], path: Path, bar: float) -> dict:
    if not path.exists():
        return {"decided": 0, "wrong_by_truth": 0, "wrong_by_graphloc": 0}
    decided = wrong = wrong_own = 0
    worst = 0.0
    with open(path, newline="") as fh:
        for row in csv.DictReader(fh):
            if int(row["committed"]) < 0 or row["robot"] not in truth:
                continue
            pos = np.array([float(row["x"]), float(row["y"]), float(row["z"])])
            if not np.all(np.isfinite(pos)):
                continue
            decided += 1
            true_pos = truth_position(truth[row["robot"]], np.array([float(row["time"])]))[0]
            miss = float(np.linalg.norm(pos - true_pos))
            worst = max(worst, miss)
            wrong += miss > bar
            wrong_own += row.get("correct", "") == "0"
    return {
        "decided": decided,
        "wrong_by_truth": wrong,
        "wrong_by_graphloc": wrong_own,
        "worst_decided_m": round(worst, 3),
    }


def _camera_of(robot: dict):
    """(K, body_T_camera) of a robot's first camera, read from its manifest entry with the
    generator's conventions (rpy = Rz Ry Rx, or a 4x4 matrix)."""
    for sensor in robot.get("sensors", []):
        if sensor.get("type") != "camera":
            continue
        p = sensor["params"]
        k = np.array([[p["fx"], 0.0, p["cx"]], [0.0, p["fy"], p["cy"]], [0.0, 0.0, 1.0]])
        ext = sensor.get("extrinsics", {"xyz": [0, 0, 0], "rpy": [0, 0, 0]})
        if isinstance(ext, dict):
            roll, pitch, yaw = ext.get("rpy", [0, 0, 0])
            body_t_cam = np.eye(4)
            body_t_cam[:3, :3] = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
            body_t_cam[:3, 3] = ext.get("xyz", [0, 0, 0])
        else:
            body_t_cam = np.asarray(ext, float)
        return sensor["name"], k, body_t_cam
    return None


def pnp_reference(run_dir, out_dir, truth: dict[str, dict] | None = None) -> dict:
    """Per decided set of >= 4 markers: the decided candidate's position error beside that of
    PnP on all the set's pixels (OpenCV SQPnP) with the target at its true pose -- what the
    pixels of that frame allow. Medians over the sets, and how many decided sets are worse
    than twice that reference and more than 0.25 m off."""
    run_dir, out_dir = Path(run_dir), Path(out_dir)
    truth = truth or read_truth(run_dir)
    manifest = json.loads((run_dir / "manifest.json").read_text())
    robots = {r["name"]: r for r in manifest["robots"]}
    decided = {}
    dec_path = out_dir / "decisions.csv"
    if dec_path.exists():
        with open(dec_path, newline="") as fh:
            for row in csv.DictReader(fh):
                if int(row["committed"]) >= 0:
                    key = (row["robot"], row["target"], round(float(row["time"]), 4))
                    decided[key] = np.array([float(row[c]) for c in "xyz"])
    dec_err, pnp_err, worse = [], [], 0
    for name, robot in robots.items():
        cam = _camera_of(robot)
        path = robot.get("tables", {}).get("markers")
        if cam is None or path is None or name not in truth:
            continue
        _, k, body_t_cam = cam
        sets: dict = {}
        with open(run_dir / path, newline="") as fh:
            for row in csv.DictReader(fh):
                key = (name, row["target"], round(float(row["time"]), 4))
                sets.setdefault(key, []).append(
                    (int(row["marker"]), float(row["u"]), float(row["v"]))
                )
        for key, obs in sets.items():
            if key not in decided or len(obs) < 4 or key[1] not in truth:
                continue
            layout = np.asarray(robots[key[1]]["markers"], float)
            if max(i for i, _, _ in obs) >= len(layout):
                continue
            tr = truth[key[1]]
            t = key[2]
            rot = Rotation.from_quat(truth_quat(tr, t)).as_matrix()
            pos = truth_position(tr, np.array([t]))[0]
            pts = (rot @ layout[[i for i, _, _ in obs]].T).T + pos
            uv = np.array([[u, v] for _, u, v in obs])
            ok, rvec, tvec = cv2.solvePnP(pts, uv, k, None, flags=cv2.SOLVEPNP_SQPNP)
            if not ok:
                continue
            cam_t_world = np.eye(4)
            cam_t_world[:3, :3] = cv2.Rodrigues(rvec)[0]
            cam_t_world[:3, 3] = tvec.ravel()
            world_t_body = np.linalg.inv(cam_t_world) @ np.linalg.inv(body_t_cam)
            true_obs = truth_position(truth[name], np.array([t]))[0]
            e_pnp = float(np.linalg.norm(world_t_body[:3, 3] - true_obs))
            e_dec = float(np.linalg.norm(decided[key] - true_obs))
            pnp_err.append(e_pnp)
            dec_err.append(e_dec)
            worse += e_dec > max(0.25, 2.0 * e_pnp)
    if not dec_err:
        return {"sets": 0}
    return {
        "sets": len(dec_err),
        "decided_median_m": round(float(np.median(dec_err)), 3),
        "pnp_all_median_m": round(float(np.median(pnp_err)), 3),
        "decided_worse_than_pnp": int(worse),
    }


def score(run_dir, out_dir, mode: str = "batch", decision_bar_m: float = 0.5) -> dict:
    """The scores of ``out_dir`` (graphloc's outputs of ``mode``) against ``run_dir``'s truth."""
    run_dir, out_dir = Path(run_dir), Path(out_dir)
    truth = read_truth(run_dir)
    robots = {}
    for name, tr in truth.items():
        est = out_dir / f"{name}_{mode}.tum"
        robots[name] = score_robot(tr, est) if est.exists() else {"unplaced": True, "n": 0}
    result: dict = {"mode": mode, "robots": robots}
    result["decisions"] = score_decisions(truth, out_dir / "decisions.csv", decision_bar_m)
    result["decisions"]["pnp_reference"] = pnp_reference(run_dir, out_dir, truth)
    placed = [r for r in robots.values() if not r.get("unplaced")]
    result["worst_final_m"] = max((r["final_m"] for r in placed), default=None)
    result["worst_max_m"] = max((r["max_m"] for r in placed), default=None)
    result["unplaced"] = sorted(n for n, r in robots.items() if r.get("unplaced"))
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--mode", choices=("batch", "online"), default="batch")
    parser.add_argument("--decision-bar", type=float, default=0.5, help="[m]")
    args = parser.parse_args(argv)
    print(json.dumps(score(args.run, args.out, args.mode, args.decision_bar), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
