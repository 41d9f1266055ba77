"""Writers of the graphloc log format: one table (`write_table`, floats lossless) and a planar
run in arrays (`PlanarRun`, the MRCLAM loader's form) as a log directory (`write_planar_run`)."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from graphloc.names import check_name, out_path, safe_name
from graphloc.manifest import write_manifest
from graphloc.records import LANDMARK_COLUMNS, LANDMARK_PREFIX, columns
from graphloc.textio import SkipReport


# ---- planar multi-robot run (numpy form) -----------------------------------------------------
@dataclass(frozen=True)
class PlanarRun:
    """A planar multi-robot run in arrays (the MRCLAM loader's form;
    `graphloc.run.team_run_from_planar` turns it into the TeamRun every pipeline takes).

    robots: R names; initial_poses: (R,3) (x, y, theta) at start_time (NaN row = unknown);
    odometry[r]: (N_r,3) time, v, omega; groundtruth[r]: (G_r,4) time, x, y, theta or None;
    observations (M rows, time-sorted): obs_time, obs_robot (observer index), obs_target_robot
    (index or -1), obs_landmark (landmark id or -1), obs_range [m], obs_bearing [rad] (robot body
    frame);
    landmark_ids (L,), landmark_xy (L,2), landmark_sigma (L,2); skips: what the loader skipped.
    """

    name: str
    robots: tuple
    start_time: float
    initial_poses: np.ndarray
    odometry: tuple
    groundtruth: tuple
    obs_time: np.ndarray
    obs_robot: np.ndarray
    obs_target_robot: np.ndarray
    obs_landmark: np.ndarray
    obs_range: np.ndarray
    obs_bearing: np.ndarray
    landmark_ids: np.ndarray
    landmark_xy: np.ndarray
    landmark_sigma: np.ndarray
    skips: SkipReport = field(default_factory=SkipReport, compare=False)
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        R = len(self.robots)
        if (
            self.initial_poses.shape != (R, 3)
            or len(self.odometry) != R
            or len(self.groundtruth) != R
        ):
            raise ValueError(
                f"PlanarRun: initial_poses must be ({R},3) and odometry/groundtruth "
                f"have {R} entries"
            )
        m = self.obs_time.shape
        for name in ("obs_robot", "obs_target_robot", "obs_landmark", "obs_range", "obs_bearing"):
            if getattr(self, name).shape != m:
                raise ValueError(
                    f"PlanarRun: {name} must have shape {m}, got {getattr(self, name).shape}"
                )
        for r, od in enumerate(self.odometry):
            if od.ndim != 2 or od.shape[1] != 3:
                raise ValueError(
                    f"PlanarRun: odometry of {self.robots[r]} must be (N,3), got {od.shape}"
                )

    @property
    def end_time(self) -> float:
        return float(min(od[-1, 0] for od in self.odometry if len(od)))


def write_planar_run(run: PlanarRun, root: str | Path) -> Path:
    """Write `run` as a graphloc log directory (manifest.json + robot tables + landmarks.csv)."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    robots = []
    for r, name in enumerate(run.robots):
        check_name(name, f"PlanarRun.robots[{r}]")
        out_path(root, name).mkdir(exist_ok=True)
        tables = {"odometry": f"{name}/odometry.csv", "range_bearing": f"{name}/range_bearing.csv"}
        od = run.odometry[r]
        write_csv(
            root / tables["odometry"],
            columns("odometry"),
            [(f"{t:.6f}", "wheels", f"{v:.6g}", f"{w:.6g}") for t, v, w in od],
        )
        sel = np.flatnonzero(run.obs_robot == r)
        rows = []
        for i in sel:
            target = (
                run.robots[run.obs_target_robot[i]]
                if run.obs_target_robot[i] >= 0
                else f"{LANDMARK_PREFIX}{run.obs_landmark[i]}"
            )
            rows.append(
                (
                    f"{run.obs_time[i]:.6f}",
                    "camera",
                    target,
                    f"{run.obs_range[i]:.6g}",
                    f"{run.obs_bearing[i]:.6g}",
                )
            )
        write_csv(root / tables["range_bearing"], columns("range_bearing"), rows)
        if run.groundtruth[r] is not None:
            tables["groundtruth"] = f"{name}/groundtruth.csv"
            write_csv(
                root / tables["groundtruth"],
                columns("groundtruth"),
                [
                    (f"{t:.6f}", f"{x:.8g}", f"{y:.8g}", f"{th:.8g}")
                    for t, x, y, th in run.groundtruth[r]
                ],
            )
        init = run.initial_poses[r]
        robots.append(
            {
                "name": name,
                "kind": "ground",
                "initial_pose": None if not np.isfinite(init).all() else [float(a) for a in init],
                "sensors": [
                    {"name": "wheels", "type": "odometry"},
                    {
                        "name": "camera",
                        "type": "range_bearing",
                        "extrinsics": [0.0, 0.0, 0.0],
                        "params": {},
                    },
                ],
                "tables": tables,
            }
        )
    write_csv(
        root / "landmarks.csv",
        LANDMARK_COLUMNS,
        [
            (int(i), f"{p[0]:.8g}", f"{p[1]:.8g}", "0", f"{s[0]:.3g}", f"{s[1]:.3g}", "0")
            for i, p, s in zip(run.landmark_ids, run.landmark_xy, run.landmark_sigma)
        ],
    )
    write_manifest(
        {
            "name": safe_name(run.name),
            "start_time": run.start_time,
            "robots": robots,
            "landmarks": {"file": "landmarks.csv"},
            "meta": run.meta,
        },
        root,
    )
    return root


def write_table(path: str | Path, table: str, rows) -> Path:
    """One table of a log: header `columns(table)`, then `rows` (floats written losslessly, so
    large time stamps keep their digits); parent folders created."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_csv(path, columns(table), rows)
    return path


def cell(v) -> str:
    """A table cell: floats written losslessly (repr), everything else as str."""
    return repr(float(v)) if isinstance(v, (float, np.floating)) else str(v)


def write_csv(path: Path, header, rows) -> None:
    """A CSV file: `header`, then `rows` (cells by `cell`)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows([cell(v) for v in row] for row in rows)
