"""The ICP stages of `graphloc.mapping.robust_registration.robust_register` (issue 16): the
coarse grid both clouds are registered on first (`coarse_clouds`, `grid_down`), the wide pyramid
above it that narrows a poor hint's reach step by step (`wide_levels`), the Tukey-weighted
point-to-plane estimation of those levels (`point_to_plane_estimation`), and the fine stage on
the prepared clouds (`fine_stage`)."""

from __future__ import annotations

import numpy as np
import open3d as o3d

from graphloc.mapping.registration import PreparedCloud, RegistrationConfig

reg_t = o3d.t.pipelines.registration
reg_l = o3d.pipelines.registration


def fine_stage(
    source: PreparedCloud, target: PreparedCloud, init: np.ndarray, cfg: RegistrationConfig
) -> tuple[np.ndarray, int]:
    """`robust_register`'s fine stage: Open3D tensor point-to-plane ICP of the prepared clouds
    from `init`, correspondences within cfg.max_correspondence[-1], a Tukey kernel of
    cfg.fine_tukey times that distance (least squares if 0), until fitness and inlier RMSE change
    by less than cfg.fine_relative (relative), cfg.max_iterations[-1] iterations at most, with
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
        reg_t.ICPConvergenceCriteria(cfg.fine_relative, cfg.fine_relative, cfg.max_iterations[-1]),
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
