"""Open3D scan registration for inter-robot map fusion (seed 004 Sec. IV).

- `prepare`: denoise as seed 004 Sec. IV.A does -- drop points far from their nearest
  neighbours (statistical outlier removal), then voxel-downsample and estimate normals
  oriented toward the sensor.
- `refine`: coarse-to-fine point-to-plane ICP from an initial guess (seed 004 Sec. IV:
  ICP converges only from a good initial estimate), with the 6x6 information matrix of the
  result from `get_information_matrix_from_point_clouds`, converted to GTSAM's Pose3 tangent
  (right perturbation) so it can weight a BetweenFactorPose3.
- `global_fpfh_ransac`: Open3D's FPFH features + RANSAC, the peer initial guess of the benchmark.
- `robust_register` (issue 16): the inter-robot registration -- multi-start around the pose
  hint, truncated point-to-plane cost, `AcceptanceConfig` checks that turn a wrong answer into
  "not fused", and a calibrated covariance (`calibrated_covariance`: the cluster-robust
  sandwich of `cluster_covariance`, scaled and floored by the model that
  `scripts/bench_fusion.py --real --calibrate` fits by maximum likelihood on calibration trials).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import gtsam
import numpy as np
import open3d as o3d

reg_t = o3d.t.pipelines.registration
reg_l = o3d.pipelines.registration


@dataclass(frozen=True)
class RegistrationConfig:
    """Denoising (nb_neighbors, std_ratio), downsampling (voxel [m]), normals (normal_radius,
    max_nn), point-to-plane ICP (scales [m], max_correspondence [m], max_iterations per stage,
    relative tolerances), FPFH + RANSAC (fpfh_radius, ransac_distance, ransac_iterations,
    ransac_confidence), and the range noise used to scale the information matrix (range_sigma
    [m]). covariance_scale and covariance_floor (rot [rad], trans [m]) calibrate
    robust_register's covariance (`calibrated_covariance`); the defaults are the fit of
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
    # width coarse_tukey voxels (0: least squares), cluster size [m] of the sandwich covariance,
    # stop at the first start whose candidate passes its checks with an inlier ratio of at least
    # stop_inlier_ratio (a candidate that barely passes may sit in a basin next to the right one)
    coarse_voxels: float = 2.0
    coarse_tukey: float = 0.5
    covariance_block: float = 0.5
    stop_at_first_valid: bool = True
    stop_inlier_ratio: float = 0.72
    # the wide level's reach is capped at max_reach [m]: beyond it a first-order covariance is no
    # basin a local method covers (the sigma points and the global fallback take over)
    max_reach: float = 1.0
    global_fallback: bool = True  # robust_register: FPFH + RANSAC start when every hint start fails
    covariance_scale: float = 17.1  # fit of docs/results_fusion_calibration.json (3 digits)
    covariance_floor: tuple[float, float] = (6.69e-4, 4.40e-4)

    def __post_init__(self):
        if not (self.voxel > 0 and self.normal_radius > 0 and self.range_sigma > 0):
            raise ValueError("RegistrationConfig: voxel, normal_radius and range_sigma must be > 0")
        if not (
            self.covariance_scale > 0
            and len(self.covariance_floor) == 2
            and min(self.covariance_floor) >= 0
        ):
            raise ValueError(
                "RegistrationConfig: covariance_scale must be > 0 and covariance_floor two values "
                ">= 0 (rot [rad], trans [m])"
            )
        n = len(self.scales)
        if n == 0 or len(self.max_correspondence) != n or len(self.max_iterations) != n:
            raise ValueError(
                "RegistrationConfig: scales, max_correspondence and max_iterations need one entry "
                "per stage"
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
    """A denoised, downsampled cloud with normals (tensor and legacy views share no memory)."""

    cloud: o3d.t.geometry.PointCloud
    legacy: o3d.geometry.PointCloud
    n_input: int
    n_outliers: int

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
    points: np.ndarray, cfg: RegistrationConfig = RegistrationConfig()
) -> tuple[o3d.t.geometry.PointCloud, int]:
    """Voxel downsampling, then statistical outlier removal (seed 004 Sec. IV.A: a point far from
    its nearest neighbours is noise); returns the cloud and the number of (voxel) outliers
    removed."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"denoise: points must be (N,3), got {pts.shape}")
    if not np.isfinite(pts).all():
        raise ValueError("denoise: points contain NaN/inf")
    if len(pts) < cfg.nb_neighbors + 1:
        raise ValueError(f"denoise: {len(pts)} points is too few (need > {cfg.nb_neighbors})")
    pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(pts)).voxel_down_sample(cfg.voxel)
    pcd, keep = pcd.remove_statistical_outliers(cfg.nb_neighbors, cfg.std_ratio)
    return pcd, int(len(keep) - keep.numpy().sum())


def prepare(
    points: np.ndarray, cfg: RegistrationConfig = RegistrationConfig(), viewpoint=(0.0, 0.0, 0.0)
) -> PreparedCloud:
    """`denoise`, then normals oriented toward `viewpoint` (the sensor, for FPFH's signed
    angles)."""
    pcd, n_out = denoise(points, cfg)
    pcd.estimate_normals(cfg.max_nn, cfg.normal_radius)
    pcd.orient_normals_towards_camera_location(
        o3d.core.Tensor(np.asarray(viewpoint, dtype=np.float64))
    )
    if len(pcd.point.positions) < 10:
        raise ValueError("prepare: fewer than 10 points left after denoising and downsampling")
    return PreparedCloud(pcd, pcd.to_legacy(), len(points), n_out)


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
    result = reg_t.multi_scale_icp(
        source.cloud,
        target.cloud,
        o3d.utility.DoubleVector(cfg.scales),
        criteria,
        o3d.utility.DoubleVector(cfg.max_correspondence),
        o3d.core.Tensor(init),
        reg_t.TransformationEstimationPointToPlane(),
    )
    T = result.transformation.numpy()
    iterations = int(result.num_iterations)
    dist = cfg.max_correspondence[-1]
    info = reg_l.get_information_matrix_from_point_clouds(source.legacy, target.legacy, dist, T)
    info = information_right(np.asarray(info), T) / cfg.range_sigma**2
    if result.fitness <= 0 or np.linalg.eigvalsh(0.5 * (info + info.T))[0] <= 0:
        raise ValueError(
            f"refine: ICP found too few correspondences within {dist} m of the initial guess "
            f"(fitness {float(result.fitness):.3f}): a wrong pose hint, "
            "or scans that do not overlap"
        )
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


def pose_errors(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(rotation error [deg], translation error [m]) of T_est against T_true."""
    E = np.linalg.inv(T_true) @ T_est
    cos = np.clip((np.trace(E[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos))), float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))


# ----------------------------------------------------------------------------- robust registration
# Issue 16: an inter-robot registration that does not slide on partial overlap, and that says
# "not fused" instead of returning a confident wrong answer.


@dataclass(frozen=True)
class AcceptanceConfig:
    """Checks a registration must pass before it is fused (see `robust_register`).

    min_overlap: inlier fraction of the source (point-to-plane |r| < c, c = residual_sigma);
    min_inlier_ratio: inliers among the source points that have a target point within the fine
    correspondence distance (a slid alignment puts points near surfaces, not on them);
    min_conditioning: smallest / largest eigenvalue of the point-to-plane Hessian with rotations
    scaled by the median source range (a plane or a corridor leaves a direction unconstrained);
    hint_gate: Mahalanobis^2 of the result against the hint under the hint's covariance,
    chi-square with 6 degrees of freedom at 99.9%; ceiling_above: the robot kinds' geometry --
    the ceiling sensor is above the ground sensor (z_G > 0) and upside down (its z axis within
    max_ceiling_tilt_deg of -z_G); hint_basin_margin: how much lower (per source point) another
    candidate's truncated cost must be to win over the hint's own candidate."""

    residual_sigma: float = 0.01
    min_overlap: float = 0.1
    min_inlier_ratio: float = 0.65
    min_conditioning: float = 1e-4
    hint_gate: float = 22.458  # scipy.stats.chi2.ppf(0.999, 6)
    ceiling_above: bool = True
    max_ceiling_tilt_deg: float = 45.0
    hint_basin_margin: float = 0.05
    distinct_deg: float = 0.5
    distinct_m: float = 0.02

    def __post_init__(self):
        if not (self.residual_sigma > 0 and self.hint_gate > 0 and self.hint_basin_margin >= 0):
            raise ValueError(
                "AcceptanceConfig: residual_sigma and hint_gate must be > 0, hint_basin_margin >= 0"
            )
        if not (0 <= self.min_overlap <= 1 and 0 <= self.min_inlier_ratio <= 1):
            raise ValueError("AcceptanceConfig: min_overlap and min_inlier_ratio lie in [0, 1]")


@dataclass(frozen=True)
class Candidate:
    """One start of the multi-start registration after coarse + fine ICP: T_target_source,
    truncated point-to-plane cost per source point (eq. in `truncated_cost`), overlap (inlier
    fraction), inlier ratio among near points, and Mahalanobis^2 to the hint."""

    start: int
    transformation: np.ndarray
    cost: float
    overlap: float
    inlier_ratio: float
    hint_d2: float

    def as_dict(self) -> dict:
        return {
            "start": self.start,
            "cost": self.cost,
            "overlap": self.overlap,
            "inlier_ratio": self.inlier_ratio,
            "hint_mahalanobis2": self.hint_d2,
            "translation_m": self.transformation[:3, 3].tolist(),
        }


@dataclass(frozen=True)
class RegistrationDecision:
    """Outcome of `robust_register`: the chosen candidate (`registration`, its
    information from the residual-scaled point-to-plane Hessian), whether every check passed,
    the failed checks' reasons, every check's (value, threshold, passed), all candidates with
    why each lost, and wall time [s]."""

    registration: Registration
    accepted: bool
    reasons: tuple
    checks: dict
    candidates: tuple
    best: int
    lost: dict
    covariance: np.ndarray
    seconds: float

    def as_dict(self) -> dict:
        return {
            "accepted": self.accepted,
            "reasons": list(self.reasons),
            "checks": {
                k: {"value": v[0], "threshold": v[1], "passed": v[2]}
                for k, v in self.checks.items()
            },
            "best_candidate": self.best,
            "candidates": [dict(c.as_dict(), lost=self.lost.get(c.start)) for c in self.candidates],
            "merged_starts": {
                k: v for k, v in self.lost.items() if k not in {c.start for c in self.candidates}
            },
            "sigma_rot_deg": np.degrees(np.sqrt(np.diag(self.covariance)[:3])).tolist(),
            "sigma_trans_m": np.sqrt(np.diag(self.covariance)[3:]).tolist(),
            "seconds": self.seconds,
        }


def hint_starts(hint: np.ndarray, cov: np.ndarray) -> list[np.ndarray]:
    """The hint and its 12 sigma points hint Exp(+-sqrt(lambda_i) v_i) along the eigenvectors of
    its 6x6 covariance (right perturbation, GTSAM tangent order rot, trans): the starts that
    cover the hint's uncertainty, a P3P covariance's long axis included."""
    lam, V = np.linalg.eigh(0.5 * (cov + cov.T))
    starts = [np.asarray(hint, dtype=float)]
    for i in range(6):
        for sign in (1.0, -1.0):
            xi = sign * np.sqrt(max(lam[i], 0.0)) * V[:, i]
            starts.append(starts[0] @ gtsam.Pose3.Expmap(xi).matrix())
    return starts


def hint_covariance(sigma_rot: float, sigma_trans: float) -> np.ndarray:
    """6x6 diagonal covariance (rot [rad], trans [m]) of a hint given by two 1-sigmas."""
    return np.diag(np.r_[np.full(3, sigma_rot**2), np.full(3, sigma_trans**2)])


def point_to_plane(source: PreparedCloud, target: PreparedCloud, T: np.ndarray, nns=None):
    """Per source point (transformed by T): point-to-plane residual to its nearest target point
    along that point's normal, the distance to it, and the Jacobian rows [(p x n)^T, n^T] of the
    residual for a left perturbation Exp(xi) T (rot, trans). Nearest neighbours: Open3D NNS
    (`nns`: a prebuilt knn index of target.points, else built here)."""
    p = source.points @ T[:3, :3].T + T[:3, 3]
    q_all = target.points
    if nns is None:
        nns = target_index(target)
    idx, d2 = nns.knn_search(o3d.core.Tensor(p), 1)
    idx = idx.numpy()[:, 0]
    n = target.cloud.point.normals.numpy().astype(float)[idx]
    r = np.einsum("ij,ij->i", p - q_all[idx], n)
    J = np.hstack([np.cross(p, n), n])
    return r, np.sqrt(d2.numpy()[:, 0].astype(float)), J


def target_index(target: PreparedCloud):
    """Open3D knn index of the target's points (for `point_to_plane`)."""
    nns = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor(target.points))
    nns.knn_index()
    return nns


def truncated_cost(r: np.ndarray, d: np.ndarray, c: float, max_dist: float) -> float:
    """Truncated least squares per source point: mean of min(r^2, c^2) / c^2, a point with no
    target point within max_dist counting 1 (an unexplained point)."""
    near = d < max_dist
    return float(np.mean(np.where(near, np.minimum(r * r, c * c) / (c * c), 1.0)))


def _coarse_clouds(source: PreparedCloud, target: PreparedCloud, cfg: RegistrationConfig):
    """Both clouds on the coarse grid: twice the larger of cfg.voxel and the source's median
    nearest-neighbour spacing (the scans' density), normals re-estimated (cfg.normal_radius)."""
    spacing = float(np.median(np.asarray(source.legacy.compute_nearest_neighbor_distance())))
    voxel = 2.0 * max(cfg.voxel, spacing)
    out = []
    for c in (source.legacy, target.legacy):
        down = c.voxel_down_sample(voxel)
        down.estimate_normals(
            o3d.geometry.KDTreeSearchParamHybrid(radius=cfg.normal_radius, max_nn=cfg.max_nn)
        )
        out.append(down)
    return out[0], out[1], voxel


def _wide_clouds(src_c, tgt_c, voxel: float, cfg: RegistrationConfig):
    """The coarse clouds on a wider grid (`voxel`), normals over at least two of its voxels."""
    out = []
    for c in (src_c, tgt_c):
        down = c.voxel_down_sample(voxel)
        radius = max(cfg.normal_radius, 2.0 * voxel)
        down.estimate_normals(
            o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=cfg.max_nn)
        )
        out.append(down)
    return out


def robust_register(
    source: PreparedCloud,
    target: PreparedCloud,
    hint: np.ndarray,
    hint_cov: np.ndarray,
    cfg: RegistrationConfig = RegistrationConfig(),
    acc: AcceptanceConfig = AcceptanceConfig(),
) -> RegistrationDecision:
    """Multi-start registration of source onto target around a pose hint, with acceptance checks.

    1. Starts: the hint and its sigma points (`hint_starts`; hint_cov is the hint's 6x6
       covariance, rot [rad] then trans [m], right perturbation: `hint_covariance` of two
       sigmas, or a P3P candidate's first-order covariance carried to the LiDAR frames).
    2. Per start: when the hint's reach (1-sigma rotation times the median source range plus 1-sigma
       translation, at most cfg.max_reach) exceeds the coarse correspondence distance, a wide level
       first: ICP on clouds gridded at reach / cfg.coarse_voxels with correspondences within the
       reach and a Tukey kernel of cfg.coarse_tukey of its voxels (the basin of a poor P3P guess);
       then point-to-plane ICP on the coarse grid (`_coarse_clouds`; correspondences within
       cfg.coarse_voxels coarse voxels, Tukey kernel of cfg.coarse_tukey voxels, so the parts that
       do not overlap are not pulled in); starts whose coarse results lie within one fine basin of
       each other (cfg.max_correspondence[-1], and the rotation moving the median source point that
       far) merge; then Open3D tensor ICP on the prepared clouds within that distance
       (cfg.max_iterations[-1]); candidates closer than acc.distinct_deg / distinct_m merge. With
       cfg.stop_at_first_valid the starts stop at the first candidate that passes its checks with an
       inlier ratio of at least cfg.stop_inlier_ratio (the hint comes first, so an easy case costs
       one start; one that barely passes lets the other starts compete on cost). If none passes and
       cfg.global_fallback, `global_fpfh_ransac` (seed 0) gives one more start (index 13), still
       subject to every check, the hint gate included.
    3. Each candidate's `truncated_cost` (c = acc.residual_sigma) and checks (overlap, inlier
       ratio, hint gate, robot geometry: `_candidate_checks`). Among those that pass, the lowest
       cost wins, except that the hint's own candidate (start 0) is kept when it passes and its
       cost is within acc.hint_basin_margin of that best (the data must clearly beat the
       hint's basin).
    4. The winner's conditioning; accepted only if every check passes.
    5. Covariance: the point-to-plane Hessian H over the inliers in a cluster-robust sandwich
       (`cluster_covariance`), converted to GTSAM's right perturbation (`information_right`),
       calibrated (`calibrated_covariance`); `inlier_rmse` is the inliers' residual standard
       deviation (n - 6 dof)."""
    start_t = time.perf_counter()
    hint = np.asarray(hint, dtype=float)
    hint_cov = np.asarray(hint_cov, dtype=float)
    if hint.shape != (4, 4) or not np.isfinite(hint).all():
        raise ValueError(f"robust_register: hint must be a finite 4x4 transform, got {hint.shape}")
    if (
        hint_cov.shape != (6, 6)
        or not np.isfinite(hint_cov).all()
        or np.linalg.eigvalsh(0.5 * (hint_cov + hint_cov.T))[0] <= 0
    ):
        raise ValueError(
            "robust_register: hint_cov must be a finite 6x6 positive definite covariance, got "
            f"shape {hint_cov.shape}"
        )
    src_c, tgt_c, voxel_c = _coarse_clouds(source, target, cfg)
    fine = cfg.max_correspondence[-1]
    kernel = reg_l.TukeyLoss(cfg.coarse_tukey * voxel_c) if cfg.coarse_tukey > 0 else reg_l.L2Loss()
    est = reg_l.TransformationEstimationPointToPlane(kernel)
    crit_c = reg_l.ICPConvergenceCriteria(1e-6, 1e-6, cfg.max_iterations[0])
    crit_f = reg_t.ICPConvergenceCriteria(
        cfg.relative_fitness, cfg.relative_rmse, cfg.max_iterations[-1]
    )
    hint_info = np.linalg.inv(0.5 * (hint_cov + hint_cov.T))
    hint_pose = gtsam.Pose3(hint)
    c = acc.residual_sigma
    nns = target_index(target)
    r_med = float(np.median(np.linalg.norm(source.points, axis=1)))
    basin_deg = float(np.degrees(fine / r_med))  # a rotation moving the median point by `fine`
    merged, coarse, cands, iterations = {}, [], [], 0

    lam = np.linalg.eigvalsh(hint_cov[:3, :3])[-1], np.linalg.eigvalsh(hint_cov[3:, 3:])[-1]
    reach = min(float(np.sqrt(lam[0]) * r_med + np.sqrt(lam[1])), cfg.max_reach)
    wide = None
    if cfg.coarse_voxels > 0 and reach > cfg.coarse_voxels * voxel_c:
        wide = _wide_clouds(src_c, tgt_c, reach / cfg.coarse_voxels, cfg)
        est_w = reg_l.TransformationEstimationPointToPlane(
            reg_l.TukeyLoss(cfg.coarse_tukey * reach / cfg.coarse_voxels)
        )

    def coarse_stage(T0: np.ndarray) -> np.ndarray:
        """The wide level (if the hint's reach exceeds the coarse one), then the coarse ICP."""
        if cfg.coarse_voxels <= 0:
            return T0
        if wide is not None:
            T0 = reg_l.registration_icp(wide[0], wide[1], reach, T0, est_w, crit_c).transformation
        res = reg_l.registration_icp(src_c, tgt_c, cfg.coarse_voxels * voxel_c, T0, est, crit_c)
        return np.asarray(res.transformation)

    def try_start(k: int, T: np.ndarray) -> bool:
        """Fine ICP from one start's coarse pose; True if its candidate passes its own checks."""
        nonlocal iterations
        same = [j for j, Tj in coarse if _within(T, Tj, basin_deg, fine)]
        if same:
            merged[k] = f"coarse stage converged within the fine basin of start {same[0]}"
            return False
        coarse.append((k, T))
        try:
            res = reg_t.icp(
                source.cloud,
                target.cloud,
                fine,
                o3d.core.Tensor(T),
                reg_t.TransformationEstimationPointToPlane(),
                crit_f,
            )
        except RuntimeError:  # Open3D: singular 6x6 system, too few correspondences from this start
            merged[k] = f"no correspondences within {fine} m"
            return False
        T, iterations = res.transformation.numpy(), iterations + int(res.num_iterations)
        same = [o.start for o in cands if not _distinct(T, o.transformation, acc)]
        if same:
            merged[k] = f"converged to the pose of start {same[0]}"
            return False
        r, d, _ = point_to_plane(source, target, T, nns)
        near = d < fine
        inl = near & (np.abs(r) < c)
        e = hint_pose.localCoordinates(gtsam.Pose3(T))
        cands.append(
            Candidate(
                k,
                T,
                truncated_cost(r, d, c, fine),
                float(inl.mean()),
                float(inl.sum() / max(near.sum(), 1)),
                float(e @ hint_info @ e),
            )
        )
        return all(v[2] for v in _candidate_checks(cands[-1], acc).values())

    starts = hint_starts(hint, hint_cov)
    found = False
    for k, T0 in enumerate(starts):
        ok = try_start(k, coarse_stage(T0))
        found = ok or found
        if ok and cfg.stop_at_first_valid and cands[-1].inlier_ratio >= cfg.stop_inlier_ratio:
            break
    if not found and cfg.global_fallback:  # the hint's neighbourhood failed: one global guess
        T_glob, _ = global_fpfh_ransac(source, target, cfg, seed=0)
        try_start(len(starts), coarse_stage(T_glob))
    if not cands:
        raise ValueError(
            f"robust_register: no start found correspondences within {fine} m: a wrong "
            "pose hint, or scans that do not overlap"
        )
    checks_of = {o.start: _candidate_checks(o, acc) for o in cands}
    valid = sorted(
        (o for o in cands if all(v[2] for v in checks_of[o.start].values())), key=lambda x: x.cost
    )
    lost = dict(merged)
    if valid:
        best = valid[0]
        hint_own = [o for o in valid if o.start == 0]
        if (
            hint_own
            and hint_own[0] is not best
            and hint_own[0].cost - best.cost <= acc.hint_basin_margin
        ):
            lost[best.start] = (
                f"truncated cost {best.cost:.4f} beats the hint's own candidate by less "
                f"than the hint-basin margin {acc.hint_basin_margin}"
            )
            best = hint_own[0]
    else:
        best = min(cands, key=lambda x: x.cost)
    for o in cands:
        if o.start == best.start or o.start in lost:
            continue
        failed = [k for k, v in checks_of[o.start].items() if not v[2]]
        lost[o.start] = (
            f"failed {', '.join(failed)}"
            if failed
            else f"truncated cost {o.cost:.4f} > {best.cost:.4f} of start {best.start}"
        )
    T = best.transformation
    r, d, J = point_to_plane(source, target, T, nns)
    inl = (d < fine) & (np.abs(r) < c)
    n_in = int(inl.sum())
    H = J[inl].T @ J[inl]
    s2 = float(r[inl] @ r[inl]) / max(n_in - 6, 1)
    D = np.diag([r_med**-1] * 3 + [1.0] * 3)
    eig = np.linalg.eigvalsh(D @ H @ D) if n_in >= 6 else np.zeros(6)
    conditioning = float(eig[0] / eig[-1]) if eig[-1] > 0 else 0.0
    if n_in >= 6 and conditioning >= acc.min_conditioning:  # else no covariance (not accepted)
        pts_in = (source.points @ T[:3, :3].T + T[:3, 3])[inl]
        cov_left = cluster_covariance(J[inl], r[inl], pts_in, H, cfg.covariance_block)
        sandwich = np.linalg.inv(information_right(np.linalg.inv(cov_left), T))
        cov = calibrated_covariance(sandwich, cfg)
        info = np.linalg.inv(cov)
    else:
        info = np.eye(6) * 1e-12
        cov = np.linalg.inv(info)
    checks = dict(checks_of[best.start])
    checks["conditioning"] = (
        conditioning,
        acc.min_conditioning,
        conditioning >= acc.min_conditioning,
    )
    why = {
        "overlap": "too little overlap",
        "inlier_ratio": "residuals inconsistent with a fit",
        "conditioning": "degenerate geometry (a direction is unconstrained)",
        "hint_mahalanobis2": "disagrees with the pose hint beyond its covariance",
        "ceiling_height_m": "ceiling robot below the ground robot",
        "ceiling_z_down_cos": "ceiling robot not upside down",
    }
    reasons = tuple(
        f"{why[k]} ({k} {v[0]:.4g} vs {v[1]:.4g})" for k, v in checks.items() if not v[2]
    )
    reg = Registration(
        T, best.overlap, float(np.sqrt(s2)), iterations, info, time.perf_counter() - start_t
    )
    return RegistrationDecision(
        reg,
        not reasons,
        reasons,
        checks,
        tuple(cands),
        best.start,
        lost,
        cov,
        time.perf_counter() - start_t,
    )


def _candidate_checks(o: Candidate, acc: AcceptanceConfig) -> dict:
    """name -> (value, threshold, passed) of the checks one candidate can fail on its own."""
    checks = {
        "overlap": (o.overlap, acc.min_overlap, o.overlap >= acc.min_overlap),
        "inlier_ratio": (
            o.inlier_ratio,
            acc.min_inlier_ratio,
            o.inlier_ratio >= acc.min_inlier_ratio,
        ),
        "hint_mahalanobis2": (o.hint_d2, acc.hint_gate, o.hint_d2 <= acc.hint_gate),
    }
    if acc.ceiling_above:
        T = o.transformation
        height, down = float(T[2, 3]), float(-T[2, 2])
        min_down = float(np.cos(np.deg2rad(acc.max_ceiling_tilt_deg)))
        checks["ceiling_height_m"] = (height, 0.0, height > 0.0)
        checks["ceiling_z_down_cos"] = (down, min_down, down >= min_down)
    return checks


def cluster_covariance(
    J: np.ndarray, r: np.ndarray, points: np.ndarray, H: np.ndarray, block: float
) -> np.ndarray:
    """Cluster-robust (sandwich) covariance of the least-squares pose, H^-1 M H^-1 with
    M = B / (B - 1) sum_b g_b g_b^T, g_b = sum_{i in b} J_i^T r_i over cubic blocks of side
    `block` (Liang & Zeger 1986; White 1980 with B clusters): residuals of points that share
    normals, voxels and sensor error are correlated, so they are summed before squaring."""
    cells = np.floor(points / block).astype(np.int64)
    _, label = np.unique(cells, axis=0, return_inverse=True)
    label = label.reshape(-1)
    B = int(label.max()) + 1
    G = np.zeros((B, 6))
    np.add.at(G, label, J * r[:, None])
    M = G.T @ G * (B / max(B - 1, 1))
    Hinv = np.linalg.inv(H)
    cov = Hinv @ M @ Hinv
    return 0.5 * (cov + cov.T)


def calibrated_covariance(cov: np.ndarray, cfg: RegistrationConfig) -> np.ndarray:
    """s P + diag(f_r^2 I3, f_t^2 I3) for the sandwich covariance P (right perturbation), with
    s = cfg.covariance_scale and (f_r, f_t) = cfg.covariance_floor. P sees the residual noise
    and its correlation within a cluster; it cannot see what the fit absorbs -- surfaces sampled
    differently in the two scans, normals smoothed over the normal radius, correspondences
    re-chosen as the pose moves -- which shows as errors larger than P in every direction (the
    scale s) and as an error that does not average down with more points (the floor). Both are
    fitted by maximum likelihood, e_i ~ N(0, s P_i + F), on calibration trials by
    `scripts/bench_fusion.py --real --calibrate`; the benchmark checks the NEES on other trials."""
    fr, ft = cfg.covariance_floor
    out = cfg.covariance_scale * np.asarray(cov, dtype=float) + np.diag([fr**2] * 3 + [ft**2] * 3)
    return 0.5 * (out + out.T)


def _within(A: np.ndarray, B: np.ndarray, rot_deg: float, trans_m: float) -> bool:
    rot, tr = pose_errors(A, B)
    return rot <= rot_deg and tr <= trans_m


def _distinct(A: np.ndarray, B: np.ndarray, acc: AcceptanceConfig) -> bool:
    rot, tr = pose_errors(A, B)
    return rot > acc.distinct_deg or tr > acc.distinct_m


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
