"""Decisions judged by the ground truth: which candidate of a set is genuine, and whether the
decided one is consistent with the truth."""

from __future__ import annotations

import gtsam
import numpy as np
from scipy.stats import chi2 as chi2_distribution

from graphloc.run import TeamRun


def genuine_candidates(run: TeamRun, decisions: list, max_time_diff: float = 0.02) -> list[int]:
    """Per decision, the genuine candidate: the one nearest the observer's true position (ground
    truth within max_time_diff of the set's time), or -1 where the run has no ground truth there."""
    out = []
    for d in decisions:
        if run.groundtruth[d.robot] is None or not len(run.groundtruth[d.robot][0]):
            out.append(-1)
        elif d.relative is not None:  # max-mixture route: nearest the true relative pose
            out.append(_genuine_relative(run, d, max_time_diff))
        else:
            truth = _truth_at(run, d.robot, d.time, max_time_diff)
            if truth is None or not len(d.candidates_xyz):
                out.append(-1)
                continue
            out.append(
                int(np.argmin(np.linalg.norm(d.candidates_xyz - truth.translation(), axis=1)))
            )
    return out


def _truth_at(run: TeamRun, r: int, t: float, max_time_diff: float, static_ok: bool = False):
    """Robot r's ground-truth pose nearest time t, None without a sample within max_time_diff
    (`static_ok`: any sample of a static robot)."""
    gt = run.groundtruth[r]
    if gt is None or not len(gt[0]):
        return None
    i = int(np.argmin(np.abs(gt[0] - t)))
    if abs(gt[0][i] - t) > max_time_diff and not (static_ok and run.robots[r].static):
        return None
    return gt[1][i]


def _genuine_relative(run: TeamRun, d, max_time_diff: float) -> int:
    """The candidate (observer body_T_target, `SetOutcome.relative`) nearest the true relative
    pose (rotation angle [rad] plus translation [m] over 0.1 m), -1 without ground truth."""
    rel = [_truth_at(run, r, d.time, max_time_diff) for r in (d.robot, d.target)]
    if any(p is None for p in rel):
        return -1
    truth = rel[0].between(rel[1])
    cost = []
    for T in d.relative:
        e = gtsam.Pose3.Logmap(truth.between(gtsam.Pose3(T)))
        cost.append(np.linalg.norm(e[:3]) + np.linalg.norm(e[3:]) / 0.1)
    return int(np.argmin(cost))


JUDGE_PROBABILITY = 0.999  # a decided candidate farther from the truth than this quantile is wrong
# the truth's own tolerance (rad, m): ground-truth accuracy, its time association (within
# max_time_diff) and calibration a log does not model (e.g. a camera that wobbles on its mount)
TRUTH_SIGMA = (0.01, 0.02)


def judge_decisions(
    run: TeamRun, decisions: list, max_time_diff: float = 0.02
) -> tuple[list[int], list[bool | None]]:
    """Each set's genuine candidate and whether the committed one is consistent with the truth:
    the sensor's true pose in the target's frame within the candidate's covariance plus
    `TRUTH_SIGMA`, at JUDGE_PROBABILITY of a chi-square with 6 degrees of freedom."""
    gate = float(chi2_distribution.ppf(JUDGE_PROBABILITY, 6))
    tolerance = np.diag(np.repeat(np.square(TRUTH_SIGMA), 3))
    correct = []
    for d in decisions:
        truth = _true_measurement(run, d, max_time_diff) if d.committed >= 0 else None
        if truth is None or d.measured is None:
            correct.append(None)
            continue
        e = gtsam.Pose3.Logmap(gtsam.Pose3(d.measured[d.committed]).between(truth))
        cov = d.measured_cov[d.committed] + tolerance
        correct.append(bool(e @ np.linalg.solve(cov, e) <= gate))
    return genuine_candidates(run, decisions, max_time_diff), correct


def _true_measurement(run: TeamRun, d, max_time_diff: float):
    """The sensor's true pose in the target's body frame at the set's time (gtsam.Pose3), None
    without ground truth of both robots there (a static target without ground truth: its
    initial pose)."""
    observer = _truth_at(run, d.robot, d.time, max_time_diff, static_ok=True)
    target = _truth_at(run, d.target, d.time, max_time_diff, static_ok=True)
    gt = run.groundtruth[d.target]
    if (gt is None or not len(gt[0])) and run.robots[d.target].static:
        target = run.robots[d.target].initial_pose
    if observer is None or target is None:
        return None
    return target.between(observer).compose(gtsam.Pose3(d.body_T_sensor))
