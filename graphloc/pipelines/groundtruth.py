"""Ground truth as the metrics and outputs use it: TUM rows converted only where used, evo's time
association (`paired`), what a ground-truth file holds (`groundtruth_written`), `alignment`."""

from __future__ import annotations

import numpy as np
from evo.core.trajectory import PoseTrajectory3D

from graphloc.eval import MAX_TIME_DIFF, associate
from graphloc.pipelines.team_graph.options import GROUNDTRUTH_RATES
from graphloc.run import TeamRun


def trajectory(times: np.ndarray, rows: np.ndarray) -> PoseTrajectory3D:
    """(N,) times and (N,7) x y z qx qy qz qw rows -> evo trajectory (evo's quaternions are w
    first)."""
    ok = np.isfinite(rows).all(axis=1)
    q = rows[ok, 3:7]
    return PoseTrajectory3D(
        positions_xyz=rows[ok, :3],
        orientations_quat_wxyz=np.column_stack([q[:, 3], q[:, :3]]),
        timestamps=np.asarray(times, dtype=float)[ok],
    )


class GroundTruth:
    """One robot's ground truth (`TeamRun.groundtruth[r]`: times, Pose3 list) as TUM rows
    x y z qx qy qz qw, each sample converted once, when first asked for (`rows`)."""

    def __init__(self, times, poses):
        self.times = np.asarray(times, dtype=float)
        self.poses = poses
        self._rows = np.full((len(self.times), 7), np.nan)
        self._done = np.zeros(len(self.times), dtype=bool)

    def rows(self, index=None) -> np.ndarray:
        """(len(index), 7) rows of the samples `index` (None: every sample)."""
        index = np.arange(len(self.times)) if index is None else np.asarray(index, dtype=int)
        rows = self._rows
        for i in np.unique(index[~self._done[index]]):
            p = self.poses[i]
            t, q = p.translation(), p.rotation().toQuaternion()
            rows[i] = (t[0], t[1], t[2], q.x(), q.y(), q.z(), q.w())
        self._done[index] = True
        return rows[index]

    def matched(self, times: np.ndarray) -> np.ndarray:
        """Sorted indices of the samples matched to `times` by the metrics' association
        (`graphloc.eval.associate`: each time's nearest sample within MAX_TIME_DIFF, or, where
        the ground truth has fewer samples, each sample near a time): every sample a metric of
        a trajectory at (a subset of) these times compares with."""
        if not len(times):
            return np.zeros(0, dtype=int)
        try:
            return np.unique(associate(self.times, times, MAX_TIME_DIFF)[0])
        except ValueError:  # no sample near any pose time
            return np.zeros(0, dtype=int)


def groundtruths(run: TeamRun) -> list:
    """Per robot, its `GroundTruth` where it has at least 3 samples (else None)."""
    return [
        None if gt is None or len(gt[0]) < 3 else GroundTruth(gt[0], gt[1])
        for gt in run.groundtruth
    ]


def groundtruth_rows(run: TeamRun, r: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Every ground-truth sample of robot r: (times (G,), rows (G,7)), None below 3 samples."""
    truth = groundtruths(run)[r]
    return None if truth is None else (truth.times, truth.rows())


def paired(truth: GroundTruth, times: np.ndarray, rows: np.ndarray):
    """(reference, estimate) evo trajectories of the pairs the metrics compare: the finite
    estimate rows against the ground-truth samples evo's association matches them with."""
    ok = np.isfinite(rows).all(axis=1)
    times, rows = np.asarray(times, dtype=float)[ok], rows[ok]
    i_ref, i_est = associate(truth.times, times, MAX_TIME_DIFF)
    return (
        trajectory(truth.times[i_ref], truth.rows(i_ref)),
        trajectory(times[i_est], rows[i_est]),
    )


def alignment(run: TeamRun, r: int, align: str | None = None) -> str:
    """How robot r's estimate is aligned to its truth (`eval.ALIGNMENTS`): `align` when given; else
    "none" when the run anchors the world, "se2" (planar) or "se3" when it does not."""
    if align is not None:
        return align
    anchored = any(robot.initial_pose is not None for robot in run.robots) or (
        run.landmarks_known and len(run.landmark_ids) > 0
    )
    if anchored:
        return "none"
    return "se2" if run.robots[r].planar else "se3"


def groundtruth_written(
    truth: GroundTruth, times: np.ndarray, rate: str = "estimate"
) -> tuple[np.ndarray, np.ndarray]:
    """(times, rows) of a robot's ground-truth file: rate "estimate", the samples matched to
    its pose times `times` (`GroundTruth.matched`); "full", every sample."""
    if rate not in GROUNDTRUTH_RATES:
        raise ValueError(f"groundtruth rate must be one of {GROUNDTRUTH_RATES}, got {rate!r}")
    index = truth.matched(times) if rate == "estimate" else np.arange(len(truth.times))
    return truth.times[index], truth.rows(index)
