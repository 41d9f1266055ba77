"""`TeamRun`, the one run type every pipeline takes: poses are gtsam.Pose3 world_T_body, a
candidate set holds target_T_sensor poses, covariances are 6x6 in GTSAM's Pose3 tangent order."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.surface import SurfacePlane
from graphloc.textio import SkipReport

NOISE_DEFAULTS = {
    "bearing_sigma": 0.02,
    "range_sigma": 0.05,
    "range_sigma_per_m": 0.035,
    "pixel_sigma": 1.0,
    "candidate_sigmas": (0.02, 0.05),
}  # where neither the log nor the user states a sensor's noise
PLANAR_SIGMA = 1e-3  # out-of-plane sigma [rad, m] of a planar robot's odometry step


@dataclass(frozen=True)
class TeamRobot:
    """One robot: state space (planar: SE(2) motion in the floor plane; static: one pose),
    initial pose (world_T_body, None if unknown) with its prior sigmas (rot [rad], trans [m]),
    the surface it climbs on, its marker layout (m,3) in the body frame, and its sensors'
    extrinsics body_T_sensor and params."""

    name: str
    kind: str
    planar: bool
    static: bool
    initial_pose: gtsam.Pose3 | None
    initial_sigma: tuple | None
    surface: SurfacePlane | None
    markers: np.ndarray | None
    identical_markers: bool
    sensors: dict  # name -> (body_T_sensor 4x4, params dict)
    surface_sigma: float | None = None  # plane distance [m] (None: GraphConfig.surface_sigma)
    attitude_sigma: float | None = None  # body_axis along the surface normal [rad] (None: free)
    body_axis: tuple = (0.0, 0.0, 1.0)
    base_radius: float | None = None  # [m] circular base (seed 003: seen as an ellipse)


@dataclass(frozen=True)
class Motion:
    """A relative-pose step of one robot: body at t0 -> body at t1, with its 6x6 covariance."""

    robot: int
    t0: float
    t1: float
    relative: gtsam.Pose3
    covariance: np.ndarray


@dataclass(frozen=True)
class PointMeasurement:
    """A bearing, range or range-bearing row: observer robot, time, sensor pose body_T_sensor,
    target robot index or -1, landmark id or -1; direction (3,) unit in the sensor frame (NaN
    for a range), range (NaN for a bearing); sigmas: bearing [rad], range [m]."""

    kind: str  # "bearing" | "range" | "range_bearing"
    time: float
    robot: int
    body_T_sensor: gtsam.Pose3
    target: int
    landmark: int
    direction: np.ndarray
    range: float
    bearing_sigma: float
    range_sigma: float


@dataclass(frozen=True)
class FeatureObservation:
    """One pixel of a feature track (seed 003 II-B, KLT): robot `robot`'s camera (body_T_sensor,
    intrinsics `camera`) sees scene point `track` at `pixel` (2,) with `pixel_sigma` [px]; the
    camera's prior on a new track's point (`feature_depth`, `feature_depth_sigma` params)."""

    time: float
    robot: int
    body_T_sensor: gtsam.Pose3
    camera: object  # graphloc.cameras.PinholeCamera
    track: int
    pixel: np.ndarray
    pixel_sigma: float
    depth_prior: tuple | None = None  # (depth, sigma) [m] of a new track's point (None: config)


@dataclass(frozen=True)
class ScanObservation:
    """One scan of robot `robot`'s scanner (body_T_sensor), a point-cloud file (`path`, read
    by `graphloc.mapping.io.read_points` when the scan is registered)."""

    time: float
    robot: int
    body_T_sensor: gtsam.Pose3
    path: Path


@dataclass(frozen=True)
class MarkerPixels:
    """The measurements a P3P candidate set was solved from: distinct markers `markers` (M,)
    of the target's layout seen at `pixels` (M,2) by `camera` (graphloc.cameras.PinholeCamera)
    with `pixel_sigma` [px] per coordinate."""

    markers: np.ndarray
    pixels: np.ndarray
    camera: object
    pixel_sigma: float


@dataclass(frozen=True)
class CandidateObservation:
    """One hypothesis set: robot `robot`'s sensor (body_T_sensor) sees robot `target`;
    candidates are target_T_sensor poses with covariances (CandidateSet.covariance); pixels:
    the marker pixels they were solved from (None: logged candidates, identical markers or a
    circle)."""

    time: float
    robot: int
    target: int
    body_T_sensor: gtsam.Pose3
    candidates: CandidateSet
    pixels: MarkerPixels | None = None


@dataclass(frozen=True)
class TeamRun:
    """A run in memory. velocity[r]: (N,3) time, v, omega (planar robots' wheel odometry);
    groundtruth[r]: (times (G,), poses: a sequence of Pose3, e.g. `PlanarPoses`) or None;
    landmarks: ids (L,), xyz (L,3), sigma (L,3) (std devs, 0 = surveyed with unknown precision);
    landmarks_known: False when the run has no landmark file (positions estimated: SLAM)."""

    name: str
    robots: tuple
    start_time: float
    velocity: tuple
    motions: tuple
    points: tuple
    observations: tuple
    groundtruth: tuple
    landmark_ids: np.ndarray
    landmark_xyz: np.ndarray
    landmark_sigma: np.ndarray
    landmarks_known: bool = True
    skips: SkipReport = field(default_factory=SkipReport, compare=False)
    contributions: dict = field(default_factory=dict, compare=False)  # table -> rows used
    meta: dict = field(default_factory=dict, compare=False)
    features: tuple = ()  # FeatureObservation, sorted by time
    scans: tuple = ()  # ScanObservation, sorted by time
    # what was read and used but is counted to be said (docs/log_format.md, "Notes"): a bag's
    # stamps re-sorted, scans thinned to the point budget
    notes: SkipReport = field(default_factory=SkipReport, compare=False)

    def index(self, name: str) -> int:
        return next(i for i, r in enumerate(self.robots) if r.name == name)

    @property
    def end_time(self) -> float:
        stamps = [od[-1, 0] for od in self.velocity if len(od)]
        stamps += (
            [m.t1 for m in self.motions]
            + [p.time for p in self.points]
            + [o.time for o in self.observations]
            + [f.time for f in self.features]
        )
        return float(max(stamps)) if stamps else self.start_time


def pose_from_xyz_quat(v) -> gtsam.Pose3:
    """(x, y, z, qx, qy, qz, qw) -> Pose3 (quaternion normalized)."""
    v = np.asarray(v, dtype=float)
    x, y, z, w = (v[3:7] / np.linalg.norm(v[3:7])).tolist()
    return gtsam.Pose3(gtsam.Rot3.Quaternion(w, x, y, z), v[:3])


def pose_from_planar(x: float, y: float, theta: float, z: float = 0.0) -> gtsam.Pose3:
    return gtsam.Pose3(gtsam.Rot3.Yaw(float(theta)), np.array([x, y, z], dtype=float))


class PlanarPoses(Sequence):
    """(N,3) x, y, theta rows as a sequence of Pose3 (`pose_from_planar`), each built when it is
    indexed: a planar ground truth is read at its own rate (tens of times the estimate's), and
    only the samples the metrics compare are ever converted (`pipelines.groundtruth`)."""

    def __init__(self, xytheta: np.ndarray):
        self.xytheta = np.asarray(xytheta, dtype=float).reshape(-1, 3)

    def __len__(self) -> int:
        return len(self.xytheta)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return PlanarPoses(self.xytheta[i])
        return pose_from_planar(*self.xytheta[i])


_PLANAR_IDX = np.array([3, 4, 2])  # SE(2) (x, y, theta) in the SE(3) tangent


def planar_covariance(cov3: np.ndarray) -> np.ndarray:
    """SE(2) covariance (..., 3, 3) (x, y, theta) -> SE(3) tangent (..., 6, 6) (rx, ry, rz, tx,
    ty, tz) with the out-of-plane directions held to PLANAR_SIGMA (one or a stack of them)."""
    cov3 = np.asarray(cov3, dtype=float)
    cov = np.zeros(cov3.shape[:-2] + (6, 6))
    cov[..., range(6), range(6)] = PLANAR_SIGMA**2
    cov[..., _PLANAR_IDX[:, None], _PLANAR_IDX] = cov3
    return cov


def team_run_from_planar(run, defaults: dict | None = None) -> TeamRun:
    """A planar run in arrays (`graphloc.log_writer.PlanarRun`, e.g. from the MRCLAM loader) as a
    TeamRun: ground robots with wheel odometry and range-bearing to robots and landmarks
    (bearings already in the body frame), planar ground truth."""
    d = {**NOISE_DEFAULTS, **(defaults or {})}
    robots = []
    for r, name in enumerate(run.robots):
        init = run.initial_poses[r]
        robots.append(
            TeamRobot(
                name,
                "ground",
                True,
                False,
                pose_from_planar(*init) if np.isfinite(init).all() else None,
                None,
                None,
                None,
                False,
                {"camera": (np.eye(4), {})},
            )
        )
    identity = gtsam.Pose3()
    rsig = np.hypot(d["range_sigma"], d["range_sigma_per_m"] * run.obs_range)
    points = tuple(
        PointMeasurement(
            "range_bearing",
            float(t),
            int(r),
            identity,
            int(tr),
            int(lm),
            np.array([np.cos(b), np.sin(b), 0.0]),
            float(rg),
            d["bearing_sigma"],
            float(rs),
        )
        for t, r, tr, lm, rg, b, rs in zip(
            run.obs_time,
            run.obs_robot,
            run.obs_target_robot,
            run.obs_landmark,
            run.obs_range,
            run.obs_bearing,
            rsig,
        )
    )
    gt = tuple(None if g is None else (g[:, 0], PlanarPoses(g[:, 1:4])) for g in run.groundtruth)
    sig = np.column_stack([run.landmark_sigma, np.zeros(len(run.landmark_ids))])
    xyz = np.column_stack([run.landmark_xy, np.zeros(len(run.landmark_ids))])
    return TeamRun(
        name=run.name,
        robots=tuple(robots),
        start_time=run.start_time,
        velocity=tuple(run.odometry),
        motions=(),
        points=points,
        observations=(),
        groundtruth=gt,
        landmark_ids=run.landmark_ids,
        landmark_xyz=xyz,
        landmark_sigma=sig,
        landmarks_known=len(run.landmark_ids) > 0,
        skips=run.skips,
        contributions={
            "odometry": int(sum(len(o) for o in run.odometry)),
            "range_bearing": len(points),
        },
        meta=dict(run.meta),
    )


def truncate(run: TeamRun, duration: float) -> TeamRun:
    """The first `duration` seconds of `run` (after its start time); the rows left out are
    counted in the run's skips (reason "after_duration")."""
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be finite > 0, got {duration}")
    end = run.start_time + duration
    kept = {
        "velocity": tuple(v[v[:, 0] <= end] for v in run.velocity),
        "motions": tuple(m for m in run.motions if m.t1 <= end),
        "points": tuple(p for p in run.points if p.time <= end),
        "observations": tuple(o for o in run.observations if o.time <= end),
        "features": tuple(f for f in run.features if f.time <= end),
        "scans": tuple(s for s in run.scans if s.time <= end),
    }
    cut = sum(len(v) for v in run.velocity) - sum(len(v) for v in kept["velocity"])
    cut += sum(
        len(getattr(run, k)) - len(kept[k])
        for k in ("motions", "points", "observations", "features")
    )
    skips = SkipReport()
    skips.merge(run.skips)
    if cut:
        skips.add("after_duration", f"{run.name}: {cut} rows after the first {duration} s", cut)
    groundtruth = tuple(
        None if g is None else (g[0][g[0] <= end], g[1][: int((g[0] <= end).sum())])
        for g in run.groundtruth
    )
    return replace(run, groundtruth=groundtruth, skips=skips, **kept)
