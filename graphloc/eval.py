"""Trajectory metrics with evo: ATE (after Umeyama alignment: SE(2) on planar positions, SE(3)
otherwise) and RPE over a fixed time step; TUM trajectory files."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from evo.core import geometry, metrics, sync
from evo.core.trajectory import PoseTrajectory3D
from evo.tools import file_interface
from scipy.spatial.transform import Rotation

from graphloc.names import written_whole


@dataclass(frozen=True)
class TrajectoryMetrics:
    """ate_* [m] over matched poses; rpe_trans_rmse [m] and rpe_rot_rmse [deg] over `rpe_delta_s`;
    n_matched: estimate/ground-truth pairs used; aligned: whether an alignment was applied."""

    ate_rmse: float
    ate_mean: float
    ate_median: float
    ate_max: float
    rpe_trans_rmse: float
    rpe_rot_rmse: float
    rpe_delta_s: float
    n_matched: int
    aligned: str

    def as_dict(self) -> dict:
        return asdict(self)


def planar_to_evo(times: np.ndarray, poses: np.ndarray) -> PoseTrajectory3D:
    """(N,) times and (N,3) planar poses (x, y, theta) -> evo PoseTrajectory3D (z = 0)."""
    t = np.asarray(times, dtype=float)
    p = np.asarray(poses, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or t.shape != (p.shape[0],):
        raise ValueError(
            f"planar trajectory must be (N,) times and (N,3) poses, got {t.shape} and {p.shape}"
        )
    if not (np.isfinite(t).all() and np.isfinite(p).all()):
        raise ValueError("planar trajectory contains NaN/inf")
    zeros = np.zeros(len(p))
    quat_wxyz = np.column_stack([np.cos(p[:, 2] / 2), zeros, zeros, np.sin(p[:, 2] / 2)])
    xyz = np.column_stack([p[:, :2], zeros])
    return PoseTrajectory3D(positions_xyz=xyz, orientations_quat_wxyz=quat_wxyz, timestamps=t)


def align_se2(reference: PoseTrajectory3D, estimate: PoseTrajectory3D) -> PoseTrajectory3D:
    """Copy of `estimate` rigidly aligned to `reference` in the plane (Umeyama on x, y);
    ValueError when the alignment is undetermined (`_umeyama`)."""
    R2, t2, _ = _umeyama(estimate.positions_xyz[:, :2].T, reference.positions_xyz[:, :2].T)
    R, t = np.eye(3), np.zeros(3)
    R[:2, :2], t[:2] = R2, t2
    return _moved(estimate, R, t)


def _rotations(traj: PoseTrajectory3D) -> Rotation:
    """The orientations of `traj` as one SciPy `Rotation` (evo keeps quaternions w, x, y, z)."""
    return Rotation.from_quat(traj.orientations_quat_wxyz[:, [1, 2, 3, 0]])


def _moved(
    traj: PoseTrajectory3D, R: np.ndarray, t: np.ndarray, scale: float = 1.0
) -> PoseTrajectory3D:
    """Copy of `traj` with every pose moved by (R, t) after its positions are scaled by `scale`:
    what evo's `scale(scale)` then `transform(T)` make of it (T @ pose for every pose), over all
    poses at once instead of one 4x4 product each."""
    quat = (Rotation.from_matrix(R) * _rotations(traj)).as_quat()[:, [3, 0, 1, 2]]
    return PoseTrajectory3D(
        positions_xyz=scale * traj.positions_xyz @ R.T + t,
        orientations_quat_wxyz=quat,
        timestamps=traj.timestamps.copy(),
    )


def relative_pose_errors(
    reference: PoseTrajectory3D, estimate: PoseTrajectory3D, delta: int
) -> tuple[np.ndarray, np.ndarray]:
    """evo's RPE over consecutive pairs `delta` poses apart (`metrics.RPE(..., delta,
    Unit.frames, all_pairs=False)`): for pairs (i, j) = (0, delta), (delta, 2 delta), ... the
    error pose E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j) of the reference Q and the estimate P (TUM RGB-D
    benchmark, Sturm et al. 2012, eq. 1), as (translation norms [m], rotation angles [deg]) --
    evo's `translation_part` and `rotation_angle_deg` relations -- computed for all pairs at
    once (evo forms one 4x4 matrix per pose and pair in Python: seconds on a long run). The
    translation of E is the reference step's rotation applied to the difference of the two
    steps' translations, so its norm is that difference's."""
    ids = np.arange(0, reference.num_poses, delta)
    i, j = ids[:-1], ids[1:]

    def steps(traj):
        R, p = _rotations(traj), traj.positions_xyz
        return R[i].inv() * R[j], R[i].inv().apply(p[j] - p[i])

    (Rq, tq), (Rp, tp) = steps(reference), steps(estimate)
    return np.linalg.norm(tp - tq, axis=1), np.degrees((Rq.inv() * Rp).magnitude())


MAX_TIME_DIFF = 0.02  # [s] default of the metrics' time association (estimate vs ground truth)
ALIGNMENTS = ("none", "se2", "se3", "sim3")


def _umeyama(source: np.ndarray, target: np.ndarray, with_scale: bool = False):
    """evo's Umeyama alignment of (d, N) points `source` onto `target` (with a scale for
    `with_scale`); a ValueError saying why, not evo's GeometryException, when the points cannot
    determine it (all at one place, or on one line in 3D: a robot that never moved)."""
    try:
        return geometry.umeyama_alignment(source, target, with_scale=with_scale)
    except geometry.GeometryException as exc:
        raise ValueError(
            f"cannot be aligned with its ground truth ({exc}: the {source.shape[1]} matched "
            f"poses do not span the plane)"
        ) from None


def _align_se3(
    reference: PoseTrajectory3D, estimate: PoseTrajectory3D, with_scale: bool = False
) -> PoseTrajectory3D:
    """Copy of `estimate` aligned to `reference` in SE(3) (evo's Umeyama; Sim(3) with
    `with_scale`, as evo's `align(correct_scale=True)`)."""
    R, t, c = _umeyama(estimate.positions_xyz.T, reference.positions_xyz.T, with_scale)
    return _moved(estimate, R, t, c if with_scale else 1.0)


def trajectory_metrics(
    reference: PoseTrajectory3D,
    estimate: PoseTrajectory3D,
    align: str = "se2",
    rpe_delta_s: float = 1.0,
    max_time_diff: float = MAX_TIME_DIFF,
    associated: bool = False,
) -> TrajectoryMetrics:
    """ATE / RPE of `estimate` against `reference` (time-associated by evo within max_time_diff;
    `associated`: the two are the pairs of `associate` already, pose i with pose i).
    align (as evo names them): "none" (the world frame the run defines), "se2" (planar: a
    rotation about z and a translation in the plane), "se3" (Umeyama, no scale) or "sim3"
    (Umeyama with scale)."""
    if align not in ALIGNMENTS:
        raise ValueError(f"align must be one of {', '.join(ALIGNMENTS)}, got {align!r}")
    if associated:
        ref, est = reference, estimate
    else:
        ref, est = _associate(reference, estimate, max_time_diff)
    if ref.num_poses < 3:
        raise ValueError(
            f"only {ref.num_poses} estimate poses have ground truth within {max_time_diff} s"
        )
    if align == "se2":
        est = align_se2(ref, est)
    elif align in ("se3", "sim3"):
        est = _align_se3(ref, est, with_scale=align == "sim3")
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    stats = ape.get_all_statistics()
    period = float(np.median(np.diff(ref.timestamps)))
    delta = max(
        1, min(int(round(rpe_delta_s / period)), ref.num_poses - 1)
    )  # short runs: the longest pair
    rpe_t, rpe_r = relative_pose_errors(ref, est, delta)
    return TrajectoryMetrics(
        ate_rmse=float(stats["rmse"]),
        ate_mean=float(stats["mean"]),
        ate_median=float(stats["median"]),
        ate_max=float(stats["max"]),
        rpe_trans_rmse=float(np.sqrt(np.mean(rpe_t**2))),
        rpe_rot_rmse=float(np.sqrt(np.mean(rpe_r**2))),
        rpe_delta_s=delta * period,
        n_matched=int(ref.num_poses),
        aligned=align,
    )


def matching_time_indices(
    stamps_1: np.ndarray, stamps_2: np.ndarray, max_diff: float
) -> tuple[np.ndarray, np.ndarray]:
    """evo's `sync.matching_time_indices(stamps_1, stamps_2, max_diff)` -- each stamp of the
    first list paired with its nearest stamp of the second within max_diff (the earlier one on a
    tie) -- over all stamps at once where stamps_2 is sorted (evo's binary-search branch, one
    stamp at a time in Python); evo's own linear search where it is not."""
    s1, s2 = np.asarray(stamps_1, dtype=float), np.asarray(stamps_2, dtype=float)
    if not len(s1) or not len(s2) or np.any(np.diff(s2) < 0):
        i1, i2 = sync.matching_time_indices(s1, s2, max_diff)
        return np.asarray(i1, dtype=int), np.asarray(i2, dtype=int)
    upper = np.minimum(np.searchsorted(s2, s1, side="right"), len(s2) - 1)
    diff_ub = s2[upper] - s1
    diff_lb = np.where(upper > 0, s1 - s2[np.maximum(upper - 1, 0)], np.inf)
    take_ub = (diff_ub <= max_diff) & (diff_ub < diff_lb)
    take_lb = ~take_ub & (diff_lb <= max_diff) & (diff_lb <= diff_ub)
    inside = (s1 >= s2[0] - max_diff) & (s1 <= s2[-1] + max_diff)
    keep = inside & (take_ub | take_lb)
    return np.flatnonzero(keep), np.where(take_ub, upper, upper - 1)[keep].astype(int)


def associate(
    reference_times: np.ndarray, estimate_times: np.ndarray, max_time_diff: float = MAX_TIME_DIFF
) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (reference indices, estimate indices) that evo's nearest-time
    `associate_trajectories(reference, estimate)` makes, from the stamps alone: from the
    trajectory with fewer poses (the estimate on a tie), each stamp's nearest stamp of the other
    within max_time_diff (evo's `matching_time_indices`). Lets a caller convert only the
    reference poses that are compared (a long ground truth at 100 Hz). No pair -> ValueError."""
    ref_t = np.asarray(reference_times, dtype=float)
    est_t = np.asarray(estimate_times, dtype=float)
    if len(est_t) > len(ref_t):
        i_ref, i_est = matching_time_indices(ref_t, est_t, max_time_diff)
    else:
        i_est, i_ref = matching_time_indices(est_t, ref_t, max_time_diff)
    if not len(i_ref):
        raise ValueError(f"only 0 estimate poses have ground truth within {max_time_diff} s")
    return np.asarray(i_ref, dtype=int), np.asarray(i_est, dtype=int)


def _associate(reference: PoseTrajectory3D, estimate: PoseTrajectory3D, max_time_diff: float):
    """evo nearest-time association; no common time stamps -> ValueError (not evo's
    SyncException)."""
    try:
        return sync.associate_trajectories(reference, estimate, max_diff=max_time_diff)
    except sync.SyncException:
        raise ValueError(
            f"only 0 estimate poses have ground truth within {max_time_diff} s"
        ) from None


def ate_over_time(
    reference: PoseTrajectory3D,
    estimate: PoseTrajectory3D,
    align: str = "se2",
    max_time_diff: float = MAX_TIME_DIFF,
    associated: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """(times, translation error [m]) of the associated (and aligned) estimate, for plots
    (`associated`: as in `trajectory_metrics`)."""
    if associated:
        ref, est = reference, estimate
    else:
        ref, est = _associate(reference, estimate, max_time_diff)
    if align == "se2":
        est = align_se2(ref, est)
    elif align in ("se3", "sim3"):
        est = _align_se3(ref, est, with_scale=align == "sim3")
    err = np.linalg.norm(est.positions_xyz - ref.positions_xyz, axis=1)
    return ref.timestamps.copy(), err


def write_tum(path: str | Path, times: np.ndarray, poses: np.ndarray) -> Path:
    """The one TUM writer (timestamp tx ty tz qx qy qz qw, via evo) for estimates, ground truth
    and scenarios: times (F,) and poses either planar (F,3) [x, y, theta], homogeneous (F,4,4)
    3D poses or (F,7) rows x y z qx qy qz qw (written as they are: no conversion per pose)."""
    path = Path(path)
    poses = np.asarray(poses, dtype=float)
    times = np.asarray(times, dtype=float)
    if poses.ndim == 3 and poses.shape[1:] == (4, 4) and len(poses) == len(times):
        trajectory = PoseTrajectory3D(poses_se3=list(poses), timestamps=times)
    elif poses.ndim == 2 and poses.shape[1] == 3 and len(poses) == len(times):
        trajectory = planar_to_evo(times, poses)
    elif poses.ndim == 2 and poses.shape[1] == 7 and len(poses) == len(times):
        trajectory = PoseTrajectory3D(
            positions_xyz=poses[:, :3],
            orientations_quat_wxyz=np.column_stack([poses[:, 6], poses[:, 3:6]]),
            timestamps=times,
        )
    else:
        raise ValueError(
            f"write_tum: need (F,) times and (F,3) planar, (F,4,4) or (F,7) poses, "
            f"got {times.shape} and {poses.shape}"
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    with written_whole(path) as tmp:
        file_interface.write_tum_trajectory_file(str(tmp), trajectory)
    return path


def read_tum(path: str | Path) -> PoseTrajectory3D:
    return file_interface.read_tum_trajectory_file(str(path))
