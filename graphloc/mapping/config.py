"""The settings of the scan algorithms, light (no Open3D, KISS-ICP or GTSAM: the command line's
options and `--config` tables of `fuse-maps` / `demo` derive from them): `OdometryConfig`
(KISS-ICP odometry, `graphloc.mapping.odometry`), `RegistrationConfig` (Open3D registration and
`robust_register`, `graphloc.mapping.registration`) and `AcceptanceConfig` (the checks a
registration must pass, `graphloc.mapping.acceptance`). Those modules re-export them."""

from __future__ import annotations

from graphloc.config_schema import config_dataclass, setting


@config_dataclass
class OdometryConfig:
    """KISS-ICP settings for indoor rooms (voxel_size ~ 1% of range as KISS-ICP's default rule)."""

    max_range: float = setting(8.0, gt=0.0, le=1000.0)
    min_range: float = setting(0.19, ge=0.0)
    voxel_size: float = setting(0.08, ge=1e-3, le=10.0)
    deskew: bool = (
        False  # simulated scans are motion-free; True for real spinning LiDARs (needs timestamps)
    )
    map_voxel: float = setting(0.03, ge=1e-3, le=10.0)  # voxel of the accumulated local map
    threads: int = setting(1, ge=0, le=256)

    def __post_init__(self):
        if not self.min_range < self.max_range:
            raise ValueError(
                f"OdometryConfig.min_range must be in [0, max_range = {self.max_range:g}), "
                f"got {self.min_range}"
            )


@config_dataclass
class RegistrationConfig:
    """Denoising (nb_neighbors, std_ratio), downsampling (voxel [m]), normals (normal_radius,
    max_nn), point-to-plane ICP (scales [m], max_correspondence [m], max_iterations per stage,
    relative tolerances), FPFH + RANSAC (fpfh_radius, ransac_distance, ransac_iterations,
    ransac_confidence), and the range noise used to scale the information matrix (range_sigma
    [m]). covariance_scale and covariance_degeneracy calibrate robust_register's covariance
    (`calibrated_covariance`); the defaults are the fit of
    `scripts/bench_fusion.py --real --calibrate` (docs/results_fusion_calibration.json)."""

    nb_neighbors: int = setting(20, ge=1, le=1000)
    std_ratio: float = 2.0
    voxel: float = setting(0.03, gt=0.0)
    # must span several LiDAR rings (~1.5 deg apart) at room ranges
    normal_radius: float = setting(0.25, gt=0.0)
    max_nn: int = setting(50, ge=1, le=1000)
    scales: tuple[float, ...] = (0.16, 0.08, 0.03)  # ICP voxel per stage (coarse to fine)
    max_correspondence: tuple[float, ...] = (0.5, 0.2, 0.05)
    max_iterations: tuple[int, ...] = (30, 30, 30)
    relative_fitness: float = 1e-7
    relative_rmse: float = 1e-7
    fpfh_voxel: float = 0.08  # FPFH + RANSAC run on this coarser grid (Open3D tutorial practice)
    fpfh_radius: float = 0.4
    fpfh_max_nn: int = setting(100, ge=1, le=1000)
    ransac_distance: float = 0.12
    ransac_iterations: int = setting(100_000, ge=1, le=10_000_000)
    ransac_confidence: float = 0.999
    range_sigma: float = setting(0.01, gt=0.0)
    # robust_register (the choice of each: docs/design_algorithms.md, "Registration settings"):
    # coarse correspondences within coarse_voxels coarse voxels, Tukey width coarse_tukey voxels
    # (0: least squares); cluster size [m] of the covariance (covariance_block) and of the cost
    # margin's standard error (margin_block); stop once a candidate passed its checks with an
    # inlier ratio of at least stop_inlier_ratio
    coarse_voxels: float = 2.0
    coarse_tukey: float = setting(0.5, ge=0.0)
    # the hint's own start runs its wide pyramid once per Tukey width here [wide-level voxels]
    hint_wide_tukey: tuple[float, ...] = (2.0, 0.5)
    # fine stage: Tukey width in fine correspondence distances (0: least squares), its stop on
    # the relative change of fitness and inlier RMSE, at most fine_iterations, on every
    # fine_stride-th prepared source point
    fine_tukey: float = setting(1.0, ge=0.0)
    fine_relative: float = setting(1e-6, gt=0.0)
    fine_iterations: int = setting(60, ge=1, le=10_000)
    fine_stride: int = setting(3, ge=1, le=1000)
    covariance_block: float = setting(0.25, gt=0.0)
    margin_block: float = setting(0.5, gt=0.0)
    # `polish`: correspondences within polish_distance [m] (0: no polish), Geman-McClure kernel
    # GMLoss(polish_kernel) (k [m^2] in k / (k + r^2)^2), polish_iterations per direction in
    # rounds until a round moves the pose less than polish_settle_deg and polish_settle_m (at
    # most polish_rounds), normals of the polish_max_nn nearest points, every k-th input point
    # (k the least stride leaving at most polish_points_per_cell per grid cell; 0: every point),
    # stop on the relative change of fitness and inlier RMSE
    polish_distance: float = setting(0.02, ge=0.0)
    polish_kernel: float = setting(0.007, ge=0.0)
    polish_iterations: int = setting(6, ge=1, le=1000)
    polish_rounds: int = setting(20, ge=1, le=1000)
    polish_settle_deg: float = setting(0.01, gt=0.0)
    polish_settle_m: float = setting(0.0005, gt=0.0)
    polish_max_nn: int = setting(20, ge=3, le=1000)
    polish_points_per_cell: float = setting(2.0, ge=0.0)
    polish_relative: float = setting(1e-6, gt=0.0)
    # `prepare`: a scan with more than max_points_per_cell input points per occupied grid cell on
    # average is first thinned at random to that many (0: never thinned)
    max_points_per_cell: float = setting(8.0, ge=0.0)
    stop_at_first_valid: bool = True
    stop_inlier_ratio: float = 0.72
    # the wide level's reach is capped at max_reach [m]: beyond it a first-order covariance is no
    # basin a local method covers (the sigma points and the global fallback take over)
    max_reach: float = 1.0
    global_fallback: bool = True  # robust_register: FPFH + RANSAC start when every hint start fails
    # fit of docs/results_fusion_calibration.json (3 digits)
    covariance_scale: float = setting(4.64, gt=0.0)
    # fit of docs/results_fusion_calibration.json (3 digits)
    covariance_degeneracy: float = setting(4.10, ge=0.0)

    def __post_init__(self):
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


@config_dataclass
class AcceptanceConfig:
    """Checks a registration must pass before it is fused (`robust_register`; why each:
    docs/design_algorithms.md, "Acceptance checks").

    misfit_weight: the cost of a source point near a target point but off its surface (an
    unexplained point costs 1); residual_sigma: the least residual scale c [m] of the checks
    (c is the two scans' own residual spread, never below this); min_overlap: inlier fraction of
    the source (|r| < c); min_inlier_ratio: inliers among the source points with a target point
    within the fine correspondence distance; contradiction_block [m] / contradiction_min_points /
    contradiction_ratio / max_contradicted: at most max_contradicted of the near points may lie in
    cubes (of at least contradiction_min_points near points) whose inlier ratio is below
    contradiction_ratio times the candidate's; min_cost_margin_se: standard errors by which every
    other valid candidate must cost more than the winner; min_conditioning: smallest / largest
    eigenvalue of the point-to-plane Hessian (rotations scaled by the median source range);
    hint_gate: Mahalanobis^2 of the result against the hint (chi-square, 6 dof, 99.9%);
    ceiling_above: the ceiling sensor above the ground sensor and upside down (its z axis within
    max_ceiling_tilt_deg of -z_G); max_sigma_rot_deg / max_sigma_trans_m: the largest 1-sigma of
    the calibrated covariance; max_overlap_shortfall: no candidate within the hint gate and the
    robot geometry may overlap this many times more than the winner; distinct_deg / distinct_m:
    candidates closer than this are one registration."""

    residual_sigma: float = setting(0.01, gt=0.0)
    misfit_weight: float = setting(4.0, ge=1.0, le=1e6)
    min_overlap: float = setting(0.1, ge=0.0, le=1.0)
    min_inlier_ratio: float = setting(0.65, ge=0.0, le=1.0)
    contradiction_block: float = setting(0.5, gt=0.0)
    contradiction_min_points: int = setting(20, ge=1, le=1_000_000)
    contradiction_ratio: float = setting(0.4, ge=0.0, le=1.0)
    max_contradicted: float = setting(0.02, ge=0.0, le=1.0)
    min_cost_margin_se: float = setting(1.0, ge=0.0)
    min_conditioning: float = setting(1e-4, ge=0.0)
    hint_gate: float = setting(22.458, gt=0.0)  # scipy.stats.chi2.ppf(0.999, 6)
    ceiling_above: bool = True
    max_ceiling_tilt_deg: float = 45.0
    max_sigma_rot_deg: float = setting(0.4, gt=0.0)
    max_sigma_trans_m: float = setting(0.02, gt=0.0)
    max_overlap_shortfall: float = setting(2.0, ge=1.0, le=1e6)
    distinct_deg: float = 0.5
    distinct_m: float = 0.02
