"""Open3D scan registration for inter-robot map fusion (seed 004 Sec. IV): the shared steps.

- `prepare`: denoise as seed 004 Sec. IV.A does -- drop points far from their nearest
  neighbours (statistical outlier removal), then voxel-downsample and estimate normals
  oriented toward the sensor.
- `refine`: coarse-to-fine point-to-plane ICP from an initial guess (seed 004 Sec. IV:
  ICP converges only from a good initial estimate), with the 6x6 information matrix of the
  result from `get_information_matrix_from_point_clouds`, converted to GTSAM's Pose3 tangent
  (right perturbation) so it can weight a BetweenFactorPose3.
- `global_fpfh_ransac`: Open3D's FPFH features + RANSAC, the peer initial guess of the benchmark;
  `icp_from_hint`: the benchmark's plain-ICP peer.

The inter-robot registration of issue 16 builds on these: `graphloc.mapping.robust_registration`
(multi-start, its winner refined by `registration_stages.polish`: full-resolution point-to-plane
both ways), `graphloc.mapping.acceptance` (its checks) and
`graphloc.mapping.registration_covariance` (its calibrated covariance).
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass

import gtsam
import numpy as np

from graphloc.config import check
from graphloc.mapping.scan_noise import grid_cells, split_half_sigma
import open3d as o3d

reg_t = o3d.t.pipelines.registration


reg_l = o3d.pipelines.registration


@dataclass(frozen=True)
class RegistrationConfig:
    """Denoising (nb_neighbors, std_ratio), downsampling (voxel [m]), normals (normal_radius,
    max_nn), point-to-plane ICP (scales [m], max_correspondence [m], max_iterations per stage,
    relative tolerances), FPFH + RANSAC (fpfh_radius, ransac_distance, ransac_iterations,
    ransac_confidence), and the range noise used to scale the information matrix (range_sigma
    [m]). covariance_scale and covariance_degeneracy calibrate robust_register's covariance
    (`calibrated_covariance`); the defaults are the fit of
    `scripts/bench_fusion.py --real --calibrate` (docs/results_fusion_calibration.json)."""

    nb_neighbors: int = 20
    std_ratio: float = 2.0
    voxel: float = 0.03
    normal_radius: float = 0.25  # must span several LiDAR rings (~1.5 deg apart) at room ranges
    max_nn: int = 50
    scales: tuple[float, ...] = (0.16, 0.08, 0.03)  # ICP voxel per stage (coarse to fine)
    max_correspondence: tuple[float, ...] = (0.5, 0.2, 0.05)
    max_iterations: tuple[int, ...] = (30, 30, 30)
    relative_fitness: float = 1e-7
    relative_rmse: float = 1e-7
    fpfh_voxel: float = 0.08  # FPFH + RANSAC run on this coarser grid (Open3D tutorial practice)
    fpfh_radius: float = 0.4
    fpfh_max_nn: int = 100
    ransac_distance: float = 0.12
    ransac_iterations: int = 100_000
    ransac_confidence: float = 0.999
    range_sigma: float = 0.01
    # robust_register: coarse correspondences within coarse_voxels coarse voxels, Tukey kernel
    # width coarse_tukey voxels (0: least squares), cluster size [m] of the covariance
    # (covariance_block) and of the cost margin's standard error (margin_block), stop once a
    # candidate passed its checks with an inlier ratio of at least stop_inlier_ratio (one that
    # barely passes may sit next to the right one)
    coarse_voxels: float = 2.0
    coarse_tukey: float = 0.5
    # ... the hint's own start runs its wide pyramid once per Tukey width here [wide-level voxels],
    # in order: a wide kernel first (where most of a view overlaps, every correspondence within
    # the reach pulls, the right ones included), then coarse_tukey's narrow one (a small overlap:
    # only the nearest surfaces pull); the sigma points use coarse_tukey
    hint_wide_tukey: tuple[float, ...] = (2.0, 0.5)
    # robust_register's fine stage: Tukey kernel width in fine correspondence distances
    # (max_correspondence[-1]; 0: least squares)
    fine_tukey: float = 1.0
    # ... and its stop: relative change of fitness and inlier RMSE (Open3D's default criterion;
    # the Tukey-weighted iterations have settled by then, docs/results_fusion_real.md), at most
    # fine_iterations iterations: a view the coarse stage left a few degrees turned on a floor
    # creeps back a little per iteration, and one cut short is a candidate at no minimum, which
    # the polish's narrower window may carry on to a slid one (a denser scan of the Redwood
    # room: test_a_denser_scan_turned_on_the_floor_is_not_fused_slid)
    fine_relative: float = 1e-6
    fine_iterations: int = 60
    # ... and its samples: every fine_stride-th prepared source point (the candidates' checks and
    # covariance use them all); the winner goes straight to `polish`, which uses every point (a
    # start that slides for all its iterations and fails costs a third)
    fine_stride: int = 3
    covariance_block: float = 0.25
    margin_block: float = 0.5
    # robust_register's last stage (`polish`): point-to-plane ICP of the full-resolution clouds,
    # both ways, correspondences within polish_distance [m] (0: no polish) and Open3D's
    # Geman-McClure kernel GMLoss(polish_kernel), weight k / (k + r^2)^2: k is a squared scale
    # [m^2], and 0.007 weighs every residual within polish_distance nearly alike (kernels of the
    # residual noise, k = (7 mm)^2 or (1 cm)^2, were less accurate on exploration seeds 200-219)
    polish_distance: float = 0.02
    polish_kernel: float = 0.007
    # ... its iterations per direction: a view dominated by one plane slides along it a little
    # per iteration (on the Redwood fragment's views 4 left the fine stage's pose a tenth of a
    # degree short where 6 did not; the TUM fragment's exploration seeds were alike at 4 to 10)
    polish_iterations: int = 6
    # ... repeated in rounds from the last midpoint until a round moves the pose less than
    # polish_settle_deg and polish_settle_m (at most polish_rounds rounds): a view the fine stage
    # left beside a wall or a tenth of a degree turned creeps back a little per round, and the
    # rounds bring it to the objective's minimum instead of stopping on the way (a view the grid
    # left decimetres along a floor takes a dozen or more; one still moving after these slides)
    polish_rounds: int = 20
    polish_settle_deg: float = 0.01
    polish_settle_m: float = 0.0005
    polish_max_nn: int = 20  # its normals: plane of the 20 nearest polish points
    # ... its points: every k-th input point, k the smallest stride leaving at most
    # polish_points_per_cell per occupied grid cell (cfg.voxel) on average (0: every input
    # point). A dense RGB-D scan holds several points per 3 cm cell, which the stride thins to
    # about the grid's own density (each of the polish's rounds costs two ICPs over them); a
    # LiDAR scan, with one or two per cell along its rings, keeps every point (a stride would
    # thin its rings alone and tilt the normals across them)
    polish_points_per_cell: float = 2.0
    polish_relative: float = 1e-6  # its stop: relative change of fitness and inlier RMSE
    # `prepare`: a scan holding more than max_points_per_cell input points per occupied grid cell
    # (cfg.voxel) on average is first thinned to that many per cell, drawn at random (`denoise`;
    # 0: never thinned). The more points a noisy surface has, the more of the cells along it its
    # noise reaches (a thicker shell of cells): the cells' centroids and normals leave the
    # surface, the coarse and fine stages' poses err more, and a right registration's
    # contradicted cubes rise past their limit (the Redwood fragment's views repeated tens of
    # times, each copy with its own noise). The checks' thresholds and the covariance's
    # calibration were fitted on views of the bundled fragments at the benchmark's density,
    # a few points per cell; this bound keeps every such view whole and brings a denser scan
    # (a depth camera close up, a LiDAR map accumulated over many sweeps) back to it
    max_points_per_cell: float = 8.0
    stop_at_first_valid: bool = True
    stop_inlier_ratio: float = 0.72
    # the wide level's reach is capped at max_reach [m]: beyond it a first-order covariance is no
    # basin a local method covers (the sigma points and the global fallback take over)
    max_reach: float = 1.0
    global_fallback: bool = True  # robust_register: FPFH + RANSAC start when every hint start fails
    covariance_scale: float = 4.64  # fit of docs/results_fusion_calibration.json (3 digits)
    covariance_degeneracy: float = 4.10  # fit of docs/results_fusion_calibration.json (3 digits)

    def __post_init__(self):
        check(
            self,
            positive=(
                "voxel",
                "normal_radius",
                "range_sigma",
                "covariance_scale",
                "fine_relative",
                "polish_relative",
                "polish_settle_deg",
                "polish_settle_m",
                "covariance_block",
                "margin_block",
            ),
            nonnegative=(
                "covariance_degeneracy",
                "polish_points_per_cell",
                "max_points_per_cell",
                "coarse_tukey",
                "fine_tukey",
                "polish_distance",
                "polish_kernel",
            ),
            integer={
                **dict.fromkeys(("polish_iterations", "polish_rounds", "fine_stride"), (1, 1000)),
                **dict.fromkeys(("nb_neighbors", "max_nn", "fpfh_max_nn"), (1, 1000)),
                "polish_max_nn": (3, 1000),
                "fine_iterations": (1, 10_000),
                "ransac_iterations": (1, 10_000_000),
            },
        )
        if not all(1 <= n <= 10_000 for n in self.max_iterations):
            bad = self.max_iterations
            raise ValueError(f"RegistrationConfig.max_iterations must be in [1, 10000], got {bad}")
        n = len(self.scales)
        if n == 0 or len(self.max_correspondence) != n or len(self.max_iterations) != n:
            raise ValueError(
                "RegistrationConfig: scales, max_correspondence and max_iterations need one entry "
                "per stage"
            )
        if not self.hint_wide_tukey or min(self.hint_wide_tukey) < 0:
            raise ValueError(
                "RegistrationConfig.hint_wide_tukey: one or more Tukey widths >= 0 expected, got "
                f"{self.hint_wide_tukey}"
            )
        if (
            min(self.scales) <= 0
            or min(self.max_correspondence) <= 0
            or min(self.max_iterations) < 1
        ):
            raise ValueError(
                "RegistrationConfig: scales, max_correspondence, max_iterations must be positive"
            )


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


def icp_from_hint(
    source: PreparedCloud,
    target: PreparedCloud,
    hint: np.ndarray,
    distance: float,
    max_iterations: int = 60,
) -> tuple[np.ndarray, float]:
    """Open3D point-to-plane ICP (legacy registration_icp, one scale) from a hint: the benchmark's
    plain-ICP peer. Returns (T_target_source, seconds)."""
    start = time.perf_counter()
    r = reg_l.registration_icp(
        source.legacy,
        target.legacy,
        distance,
        np.asarray(hint, dtype=float),
        reg_l.TransformationEstimationPointToPlane(),
        reg_l.ICPConvergenceCriteria(1e-7, 1e-7, max_iterations),
    )
    return np.asarray(r.transformation), time.perf_counter() - start
