"""The ICP stages of `graphloc.mapping.robust_registration.robust_register` (issue 16): the
coarse grid both clouds are registered on first (`coarse_clouds`, `grid_down`), the wide pyramid
above it that narrows a poor hint's reach step by step (`wide_levels`), the Tukey-weighted
point-to-plane estimation of those levels (`point_to_plane_estimation`), the fine stage on
the prepared clouds (`fine_stage`), and the last stage at full resolution (`polish`)."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
import open3d as o3d

from graphloc.mapping.registration import (
    PreparedCloud,
    RegistrationConfig,
    poses_within,
)
from graphloc.mapping.registration_index import NearestIndex

reg_t = o3d.t.pipelines.registration
reg_l = o3d.pipelines.registration


def fine_stage(
    source: PreparedCloud, target: PreparedCloud, init: np.ndarray, cfg: RegistrationConfig
) -> tuple[np.ndarray, int]:
    """`robust_register`'s fine stage: Open3D tensor point-to-plane ICP of the prepared clouds
    from `init`, correspondences within cfg.max_correspondence[-1], a Tukey kernel of
    cfg.fine_tukey times that distance (least squares if 0), until fitness and inlier RMSE change
    by less than cfg.fine_relative (relative), cfg.fine_iterations iterations at most, with
    every cfg.fine_stride-th source point as a sample. Returns (T_target_source, iterations);
    Open3D raises RuntimeError when too few correspondences are left for the 6x6 system."""
    fine = cfg.max_correspondence[-1]
    rk = reg_t.robust_kernel
    kernel = (
        rk.RobustKernel(rk.RobustKernelMethod.TukeyLoss, cfg.fine_tukey * fine)
        if cfg.fine_tukey > 0
        else rk.RobustKernel()
    )
    src = source.cloud
    if cfg.fine_stride > 1:
        n = len(src.point.positions)
        src = src.select_by_index(o3d.core.Tensor(np.arange(0, n, cfg.fine_stride)))
    res = reg_t.icp(
        src,
        target.cloud,
        fine,
        o3d.core.Tensor(np.asarray(init, dtype=np.float64)),
        reg_t.TransformationEstimationPointToPlane(kernel),
        reg_t.ICPConvergenceCriteria(cfg.fine_relative, cfg.fine_relative, cfg.fine_iterations),
    )
    return res.transformation.numpy(), int(res.num_iterations)


def grid_down(cloud: o3d.geometry.PointCloud, voxel: float) -> o3d.geometry.PointCloud:
    """`cloud` on a grid of `voxel`, each cell's normal the mean of the cloud's normals in it,
    renormalized (the prepared clouds' normals are oriented toward their sensor, so they average
    rather than cancel; no second normal estimation per level)."""
    down = cloud.voxel_down_sample(voxel)
    n = np.asarray(down.normals)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    keep = norm[:, 0] > 0.5  # a cell whose normals disagree by more than 120 deg has no plane
    n[keep] /= norm[keep]
    return down.select_by_index(np.flatnonzero(keep)) if not keep.all() else down


def coarse_clouds(source: PreparedCloud, target: PreparedCloud, cfg: RegistrationConfig):
    """Both clouds on the coarse grid: twice the larger of cfg.voxel and the source's median
    nearest-neighbour spacing (the scans' density), normals averaged (`grid_down`)."""
    spacing = float(np.median(np.asarray(source.legacy.compute_nearest_neighbor_distance())))
    voxel = 2.0 * max(cfg.voxel, spacing)
    return grid_down(source.legacy, voxel), grid_down(target.legacy, voxel), voxel


def wide_levels(src_c, tgt_c, reach: float, coarse_reach: float, cfg: RegistrationConfig):
    """The wide pyramid above the coarse level: correspondences within `reach`, halved per level
    while they exceed `coarse_reach`; each level's clouds are the coarse clouds on a grid of
    reach / cfg.coarse_voxels, normals over at least two of its voxels. Returns
    [(source, target, reach, voxel)], widest first."""
    levels = []
    while reach > coarse_reach:
        voxel = reach / cfg.coarse_voxels
        pair = []
        for c in (src_c, tgt_c):
            down = c.voxel_down_sample(voxel)
            radius = max(cfg.normal_radius, 2.0 * voxel)
            down.estimate_normals(
                o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=cfg.max_nn)
            )
            pair.append(down)
        levels.append((pair[0], pair[1], reach, voxel))
        reach /= 2.0
    return levels


def point_to_plane_estimation(tukey: float):
    """Open3D point-to-plane estimation with a Tukey kernel of width `tukey` [m] (0: least
    squares)."""
    kernel = reg_l.TukeyLoss(tukey) if tukey > 0 else reg_l.L2Loss()
    return reg_l.TransformationEstimationPointToPlane(kernel)


def polish(
    source: PreparedCloud,
    target: PreparedCloud,
    T: np.ndarray,
    cfg: RegistrationConfig,
    target_nns=None,
) -> Polished:
    """The last stage of `robust_register`: point-to-plane ICP of the full-resolution clouds
    (`PreparedCloud.raw`) from T, source onto target and target onto source (correspondences
    within cfg.polish_distance, Geman-McClure kernel cfg.polish_kernel, each view cut to the mutual
    overlap), then the midpoint of the two on SE(3) (`Pose3.slerp`); in rounds from the last
    midpoint until the pose settles or cycles (at most cfg.polish_rounds). `target_nns`: a prebuilt
    `NearestIndex` of target.points, else built here. Returns T_target_source as a `Polished`
    (unchanged and settled when there is nothing to polish; not settled when the last round
    still moved it)."""
    T = np.asarray(T, dtype=float)
    if cfg.polish_distance <= 0 or source.raw is None or target.raw is None:
        return Polished(T, 0, True)
    full, cut_at, recut_deg = None, T, 0.0
    settle = cfg.polish_settle_deg, cfg.polish_settle_m
    for k in range(cfg.polish_rounds):
        if full is None or not poses_within(T, cut_at, recut_deg, cfg.voxel):
            full, cut_at = _overlap_cut(source, target, T, cfg, target_nns), T
            if full is None:
                return Polished(T, k, True)
            reach = float(np.median(np.linalg.norm(np.asarray(full[0].points), axis=1)))
            recut_deg = float(np.degrees(cfg.voxel / max(reach, cfg.voxel)))
            visited = []  # the rounds' poses on this cut
        moved = _midpoint_round(full, T, cfg)
        if moved is None:
            return Polished(T, k, True)
        visited.append(T)
        T = moved
        # settled: a round that moved the pose less than the settle thresholds, or one that
        # brought it back to a pose an earlier round left (the nearest neighbours' pairings
        # cycling among a few poses that close around the minimum)
        if any(poses_within(T, P, *settle) for P in visited):
            return Polished(T, k + 1, True, tuple(full))
    return Polished(T, cfg.polish_rounds, False, tuple(full))


@dataclass(frozen=True)
class Polished:
    """`polish`'s result: T_target_source, the rounds it ran (0: none), whether the last one
    moved the pose less than cfg.polish_settle_deg / polish_settle_m (or none could run), and
    `views`: the two clouds its last round registered (source in the source frame, target in
    the target frame, with normals; None when no round ran), for the covariance of its
    estimate (`graphloc.mapping.registration_covariance.polish_influence`)."""

    transformation: np.ndarray
    rounds: int
    settled: bool
    views: tuple | None = None


def _overlap_cut(source, target, T, cfg, target_nns) -> list | None:
    """`polish`'s two views cut to their mutual overlap at T, with normals; None when either
    keeps fewer than cfg.polish_max_nn points."""
    margin = cfg.polish_distance + cfg.voxel  # a grid cell's reach, plus the polish's
    full = []
    for c, other, M, index in (
        (source, target, T, target_nns),
        (target, source, np.linalg.inv(T), None),
    ):
        p = c.raw @ M[:3, :3].T + M[:3, 3]  # in the other view's frame
        if index is None or index.radius < margin:
            index = NearestIndex(other.points, margin)
        keep = index.nearest(p)[1] < margin
        if keep.sum() < cfg.polish_max_nn:
            return None
        full.append(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(c.raw[keep])))
        full[-1].estimate_normals(o3d.geometry.KDTreeSearchParamKNN(cfg.polish_max_nn))
    return full


def _midpoint_round(full: list, T: np.ndarray, cfg: RegistrationConfig) -> np.ndarray | None:
    """One `polish` round from T: both directions' ICP, then their midpoint on SE(3); None when
    a direction finds no correspondence within cfg.polish_distance."""
    est = reg_l.TransformationEstimationPointToPlane(reg_l.GMLoss(cfg.polish_kernel))
    crit = reg_l.ICPConvergenceCriteria(
        cfg.polish_relative, cfg.polish_relative, cfg.polish_iterations
    )
    out = []
    for a, b, T0 in ((full[0], full[1], T), (full[1], full[0], np.linalg.inv(T))):
        res = reg_l.registration_icp(a, b, cfg.polish_distance, T0, est, crit)
        if res.fitness <= 0:  # no correspondence within the distance
            return None
        out.append(np.asarray(res.transformation))
    fwd, bwd = out
    return gtsam.Pose3(fwd).slerp(0.5, gtsam.Pose3(np.linalg.inv(bwd))).matrix()
