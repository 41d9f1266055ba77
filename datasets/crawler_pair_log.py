"""The `crawler-pair` run as a log (docs/log_format.md): seed 003's front-end output (KLT
features, the teammate's base ellipse), zero-motion steps for the camera (seed eq. 8), the
teammate's odometry and ground surface (docs/design_datasets.md, "crawler-pair")."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from graphloc.datasets.camera_track import stack_poses
from graphloc.eval import write_tum
from graphloc.manifest import write_manifest
from graphloc.log_writer import write_table
from graphloc.seams import MotionNoise
from graphloc.vision.circle import rotations_from_normals
from graphloc.vision.teammate import TeammateConfig, pixel_sigmas
from graphloc.structured import dumps_json

FRAME_DT = 1.0  # [s] between frames (the seed gives no frame rate; the graph needs only order)
STILL_SIGMA = 1e-3  # [rad, m] zero-motion step of a teammate that stood still
UPRIGHT_SIGMA = 0.05  # [rad] the teammate's y axis stays vertical (ground roughness)
CRAWL_ROT_SIGMA = 0.05  # [rad] heading change of one teammate crawl
CRAWL_LATERAL = 0.25  # lateral sigma per metre crawled


def _relative_row(t0, t1, sensor, t=(0.0, 0.0, 0.0), rot=1e-3, trans=(1e-3,) * 3) -> list:
    # columns of relative_pose3: time, sensor, time0, tx ty tz, qx qy qz qw, sigmas rx..tz
    return [float(t1), sensor, float(t0), *t, 0.0, 0.0, 0.0, 1.0, rot, rot, rot, *trans]


def write_crawler_pair_log(
    seq, frames: list, out_dir, motion: MotionNoise = MotionNoise(), meta: dict | None = None
) -> Path:
    """A rendered `CrawlerPairSequence` and its front-end frames (`measure_frames`) -> a log
    directory; returns the manifest path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = seq.config
    times = FRAME_DT * np.arange(len(frames))
    floors = TeammateConfig(radius=cfg.base_radius)
    features, ellipses, cam_motion, mate_motion = [], [], [], []
    last_seen, moved, dist, var = None, False, 0.0, 0.0
    for k, f in enumerate(frames):
        t = float(times[k])
        if k > 0:
            rot, trans = motion.sigmas(bool(f.camera_moved))
            cam_motion.append(_relative_row(times[k - 1], t, "motion", rot=rot, trans=(trans,) * 3))
            if f.teammate_moved:
                moved = True
                dist += float(f.teammate_odometry)
                var += float(f.teammate_odometry_std) ** 2
        ids, pixels = np.asarray(f.features.ids), np.asarray(f.features.pixels, float)
        for j, (u, v) in zip(ids.tolist(), pixels):
            if np.isfinite([u, v]).all():
                features.append([t, "cam", int(j), float(u), float(v)])
        if f.teammate is None:
            continue
        cands = f.teammate.candidates
        sigma_c, sigma_r = pixel_sigmas(cands, floors)
        ellipses.append([t, "cam", "teammate", *cands.meta["ellipse"], sigma_c, sigma_r])
        if last_seen is not None:
            if moved:
                lateral = CRAWL_LATERAL * dist + STILL_SIGMA
                row = _relative_row(
                    last_seen,
                    t,
                    "odometry",
                    (0.0, 0.0, -dist),
                    CRAWL_ROT_SIGMA,
                    (lateral, lateral, float(np.sqrt(var))),
                )
            else:
                row = _relative_row(
                    last_seen, t, "odometry", rot=STILL_SIGMA, trans=(STILL_SIGMA,) * 3
                )
            mate_motion.append(row)
        last_seen, moved, dist, var = t, False, 0.0, 0.0
    write_table(out / "camera_features.csv", "features", features)
    write_table(out / "camera_ellipses.csv", "ellipses", ellipses)
    write_table(out / "camera_motion.csv", "relative_pose3", cam_motion)
    write_table(out / "teammate_motion.csv", "relative_pose3", mate_motion)
    write_tum(out / "camera_groundtruth.tum", times, stack_poses(seq.R_wc, seq.t_wc))
    R_disk = rotations_from_normals(seq.base_normal)
    write_tum(out / "teammate_groundtruth.tum", times, stack_poses(R_disk, seq.base_centre))
    camera_params = {
        **seq.camera.params(),
        "pixel_sigma": 1.0,  # seed III: KLT pixel variance 1
        "feature_depth": cfg.background_distance,  # seed III: KLT points start at 260 cm
        "feature_depth_sigma": 1.0,
    }
    manifest = {
        "name": "crawler-pair",
        "robots": [
            {
                "name": "camera",
                "kind": "ground",
                "planar": False,
                "initial_pose": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
                "initial_sigma": [1e-4, 1e-4],
                "sensors": [
                    {"name": "cam", "type": "camera", "params": camera_params},
                    {"name": "motion", "type": "odometry"},
                ],
                "tables": {
                    "features": "camera_features.csv",
                    "ellipses": "camera_ellipses.csv",
                    "relative_pose3": "camera_motion.csv",
                    "groundtruth": "camera_groundtruth.tum",
                },
            },
            {
                "name": "teammate",
                "kind": "ground",
                "planar": False,
                "base_radius": cfg.base_radius,
                "surface": {
                    "point": [0.0, cfg.camera_height - cfg.base_radius, 0.0],
                    "normal": [0.0, -1.0, 0.0],
                    "distance_sigma": 0.0,
                    "attitude_sigma": UPRIGHT_SIGMA,
                    "body_axis": [0.0, 1.0, 0.0],
                },
                "sensors": [{"name": "odometry", "type": "odometry"}],
                "tables": {
                    "relative_pose3": "teammate_motion.csv",
                    "groundtruth": "teammate_groundtruth.tum",
                },
            },
        ],
        "meta": json.loads(dumps_json(meta or {}, default=str)),
    }
    return write_manifest(manifest, out)
