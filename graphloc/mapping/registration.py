"""Open3D scan registration for inter-robot map fusion (seed 004 Sec. IV): the shared steps.
`prepare` denoises as Sec. IV.A does (statistical outlier removal), voxel-downsamples and
estimates normals towards the sensor; `refine` is coarse-to-fine point-to-plane ICP from an
initial guess with its information matrix in GTSAM's Pose3 tangent; `global_fpfh_ransac` is
Open3D's FPFH + RANSAC, the benchmark's peer guess. The robust registration builds on these
(`robust_registration`, `acceptance`, `registration_covariance`).
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass

import gtsam
import numpy as np

from graphloc.mapping.config import RegistrationConfig
from graphloc.mapping.scan_noise import grid_cells, split_half_sigma
import open3d as o3d

reg_t = o3d.t.pipelines.registration


reg_l = o3d.pipelines.registration


@dataclass(frozen=True)
class PreparedCloud:
    """A denoised, downsampled cloud with normals (tensor and legacy views share no memory),
    `raw`: the input points at full resolution (for the last stage of `robust_register`,
    `polish`; None when cfg.polish_distance is 0; every k-th one beyond
    cfg.polish_points_per_cell per grid cell), `n_used`: how many of the n_input points were
    gridded (fewer on a scan denser than cfg.max_points_per_cell),
    and `residual_spread`: the scan's own point-to-plane residual spread [m] on this grid
    (`graphloc.mapping.scan_noise.split_half_sigma`; the scale of robust_register's checks)."""

    cloud: o3d.t.geometry.PointCloud
    legacy: o3d.geometry.PointCloud
    n_input: int
    n_outliers: int
    raw: np.ndarray | None = None
    residual_spread: float = float("nan")
    n_used: int = 0  # the input points gridded (fewer than n_input: cfg.max_points_per_cell)

    @property
    def points(self) -> np.ndarray:
        return self.cloud.point.positions.numpy().astype(float)


@dataclass(frozen=True)
class Registration:
    """T_target_source (4,4); fitness (inlier fraction of the source), inlier RMSE [m], ICP
    iterations, information (6,6) in GTSAM Pose3 tangent order (rot, trans) for the right
    perturbation T Exp(xi), and wall time [s]."""

    transformation: np.ndarray
    fitness: float
    inlier_rmse: float
    iterations: int
    information: np.ndarray
    seconds: float


def denoise(
    points: np.ndarray, cfg: RegistrationConfig = RegistrationConfig(), max_points_per_cell=0.0
) -> tuple[o3d.t.geometry.PointCloud, int, np.ndarray | None]:
    """Voxel downsampling, then statistical outlier removal (seed 004 Sec. IV.A: a point far from
    its nearest neighbours is noise). With max_points_per_cell > 0, a scan holding more points
    than that per occupied cell on average is gridded again from that many per cell, drawn at
    random (seeded: the same scan gives the same cloud; a stride would pick one ring or column
    of an organized scan). Returns the cloud, the number of (voxel) outliers removed and the
    indices of the points gridded, in their order (None: every point)."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"denoise: points must be (N,3), got {pts.shape}")
    if not np.isfinite(pts).all():
        raise ValueError("denoise: points contain NaN/inf")
    if len(pts) < cfg.nb_neighbors + 1:
        raise ValueError(f"denoise: {len(pts)} points is too few (need > {cfg.nb_neighbors})")
    # sorted cells: the fine stage's every-k-th sample is the same in every run and process
    cells = grid_cells(pts, cfg.voxel)
    budget, kept = int(max_points_per_cell * len(cells)), None
    if 0 < budget < len(pts):
        kept = np.sort(np.random.default_rng(0).choice(len(pts), budget, replace=False))
        cells = grid_cells(pts[kept], cfg.voxel)
    pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(cells))
    pcd, keep = pcd.remove_statistical_outliers(cfg.nb_neighbors, cfg.std_ratio)
    return pcd, int(len(keep) - keep.numpy().sum()), kept


def prepare(points, cfg=RegistrationConfig(), viewpoint=(0.0, 0.0, 0.0), inter_robot=True):
    """`denoise` (a scan denser than cfg.max_points_per_cell per grid cell thinned first), then
    normals oriented toward `viewpoint` (the sensor, for FPFH's signed angles). With
    `inter_robot`, also what `robust_register` needs: the scan's residual spread
    (`split_half_sigma`) and, with cfg.polish_distance > 0, the input points (`raw`; every k-th
    beyond cfg.polish_points_per_cell per grid cell); scan matching of consecutive scans
    (`refine`) needs neither. Returns a `PreparedCloud`."""
    pcd, n_out, kept = denoise(points, cfg, cfg.max_points_per_cell)
    pts = np.asarray(points, dtype=np.float64)
    pts = pts if kept is None else pts[kept]
    pcd.estimate_normals(cfg.max_nn, cfg.normal_radius)
    pcd.orient_normals_towards_camera_location(
        o3d.core.Tensor(np.asarray(viewpoint, dtype=np.float64))
    )
    if len(pcd.point.positions) < 10:
        raise ValueError("prepare: fewer than 10 points left after denoising and downsampling")
    if not inter_robot:
        return PreparedCloud(pcd, pcd.to_legacy(), len(points), n_out, n_used=len(pts))
    raw = None
    if cfg.polish_distance > 0:
        raw = pts
        budget = int(cfg.polish_points_per_cell * len(pcd.point.positions))
        if 0 < budget < len(raw):
            raw = raw[:: -(-len(raw) // budget)]
    fine = cfg.max_correspondence[-1]
    spread = split_half_sigma(pts, cfg.voxel, cfg.normal_radius, cfg.max_nn, fine)
    return PreparedCloud(pcd, pcd.to_legacy(), len(points), n_out, raw, spread, len(pts))


def information_right(info_left: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Open3D's information is for a left perturbation Exp(xi_L) T (target frame); GTSAM's
    BetweenFactorPose3 uses T Exp(xi_R), xi_L = Ad_T xi_R, so Lambda_R = Ad_T^T Lambda_L Ad_T."""
    ad = gtsam.Pose3(T).AdjointMap()
    out = ad.T @ info_left @ ad
    return 0.5 * (out + out.T)


def refine(
    source: PreparedCloud,
    target: PreparedCloud,
    init: np.ndarray,
    cfg: RegistrationConfig = RegistrationConfig(),
) -> Registration:
    """Coarse-to-fine ICP of source onto target from `init` (Open3D multi_scale_icp: one stage per
    entry of cfg.scales / max_correspondence / max_iterations)."""
    init = np.asarray(init, dtype=np.float64)
    if init.shape != (4, 4) or not np.isfinite(init).all():
        raise ValueError(f"refine: init must be a finite 4x4 transform, got shape {init.shape}")
    start = time.perf_counter()
    criteria = [
        reg_t.ICPConvergenceCriteria(cfg.relative_fitness, cfg.relative_rmse, n)
        for n in cfg.max_iterations
    ]
    dist = cfg.max_correspondence[-1]
    too_few = (
        f"refine: ICP found too few correspondences within {dist} m of the initial guess "
        "(fitness {:.3f}): a wrong pose hint, or scans that do not overlap"
    )
    try:
        result = reg_t.multi_scale_icp(
            source.cloud,
            target.cloud,
            o3d.utility.DoubleVector(cfg.scales),
            criteria,
            o3d.utility.DoubleVector(cfg.max_correspondence),
            o3d.core.Tensor(init),
            reg_t.TransformationEstimationPointToPlane(),
        )
    except RuntimeError as exc:  # Open3D: a singular 6x6 system, too few correspondences left
        why = re.sub(r"\x1b\[[0-9;]*m", "", str(exc)).strip().rsplit(": ", 1)[-1]
        raise ValueError(f"{too_few.format(0.0)}; Open3D: {why}") from None
    T, iterations = result.transformation.numpy(), int(result.num_iterations)
    info = reg_l.get_information_matrix_from_point_clouds(source.legacy, target.legacy, dist, T)
    info = information_right(np.asarray(info), T) / cfg.range_sigma**2
    if result.fitness <= 0 or np.linalg.eigvalsh(0.5 * (info + info.T))[0] <= 0:
        raise ValueError(too_few.format(float(result.fitness)))
    seconds = time.perf_counter() - start
    return Registration(
        T, float(result.fitness), float(result.inlier_rmse), iterations, info, seconds
    )


def global_fpfh_ransac(
    source: PreparedCloud,
    target: PreparedCloud,
    cfg: RegistrationConfig = RegistrationConfig(),
    seed: int = 0,
) -> tuple[np.ndarray, float]:
    """FPFH + RANSAC global registration (Open3D) on clouds downsampled to cfg.fpfh_voxel (normals
    re-estimated at 2 voxels); returns (T_target_source, seconds including downsampling and
    features)."""
    start = time.perf_counter()
    o3d.utility.random.seed(int(seed))
    coarse = []
    for cloud in (source.legacy, target.legacy):
        c = cloud.voxel_down_sample(cfg.fpfh_voxel)
        c.estimate_normals(
            o3d.geometry.KDTreeSearchParamHybrid(radius=2 * cfg.fpfh_voxel, max_nn=30)
        )
        c.orient_normals_towards_camera_location(np.zeros(3))
        coarse.append(c)
    src, tgt = coarse
    param = o3d.geometry.KDTreeSearchParamHybrid(radius=cfg.fpfh_radius, max_nn=cfg.fpfh_max_nn)
    f_src = reg_l.compute_fpfh_feature(src, param)
    f_tgt = reg_l.compute_fpfh_feature(tgt, param)
    checkers = [
        reg_l.CorrespondenceCheckerBasedOnEdgeLength(0.9),
        reg_l.CorrespondenceCheckerBasedOnDistance(cfg.ransac_distance),
    ]
    result = reg_l.registration_ransac_based_on_feature_matching(
        src,
        tgt,
        f_src,
        f_tgt,
        True,
        cfg.ransac_distance,
        reg_l.TransformationEstimationPointToPoint(False),
        3,
        checkers,
        reg_l.RANSACConvergenceCriteria(cfg.ransac_iterations, cfg.ransac_confidence),
    )
    return np.asarray(result.transformation), time.perf_counter() - start


def poses_within(A: np.ndarray, B: np.ndarray, rot_deg: float, trans_m: float) -> bool:
    """True if A and B differ by at most rot_deg and trans_m."""
    rot, trans = pose_errors(A, B)
    return rot <= rot_deg and trans <= trans_m


def pose_errors(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(rotation error [deg], translation error [m]) of T_est against T_true."""
    E = np.linalg.inv(T_true) @ T_est
    cos = np.clip((np.trace(E[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos))), float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))
