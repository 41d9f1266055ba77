"""`SetOutcome`: the team graph's record of one candidate set (not `seams.Decision`, one
tracker update), and the helpers the tracked and max-mixture streams share."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np


@dataclass
class SetOutcome:
    """What happened to one candidate set: where each candidate puts the observer's body, the
    committed candidate (-1: none), its posterior (else the largest) and pose (x y z qx qy qz
    qw), the candidates of the committed one's pose (`same_pose`); status "decided",
    "undecided" or "inconsistent"; measured / measured_cov / body_T_sensor: what the truth
    judges a decision by. A max-mixture set is chosen by the solve (`solve.choose_mixtures`)."""

    time: float
    robot: int
    target: int
    candidates_xyz: np.ndarray
    committed: int
    probability: float
    pose: np.ndarray
    same_pose: list
    probabilities: np.ndarray | None = None  # (K,) every candidate's posterior (tracker)
    mixture: object = None  # max-mixture route: the MaxMixture (chosen at the estimate)
    relative: np.ndarray | None = None  # max-mixture route: (K,4,4) observer body_T_target
    candidates_quat: np.ndarray | None = None  # (K,4) x y z w: the body orientation each gives
    status: str = "undecided"
    measured: np.ndarray | None = None  # (K,4,4) target_T_sensor per candidate
    measured_cov: np.ndarray | None = None  # (K,6,6) their covariances
    body_T_sensor: np.ndarray | None = None  # (4,4)


SAME_POSE_GATE = 12.59  # chi2(6) at 95 %: two candidates this close are one pose for the decision


def same_pose(poses: list, cov: np.ndarray, j: int) -> list[int]:
    """Candidate j and the candidates that are the same pose within their covariances
    (Mahalanobis^2 of the difference below SAME_POSE_GATE): near the P3P fold two solutions
    nearly coincide and share the posterior, and either one is the answer."""
    out = []
    for i, p in enumerate(poses):
        e = gtsam.Pose3.Logmap(poses[j].between(p))
        if i == j or e @ np.linalg.solve(cov[i] + cov[j], e) < SAME_POSE_GATE:
            out.append(i)
    return out


def inconsistent(o, r: int, ti: int) -> SetOutcome:
    """The record of a set no candidate of which passed the pixel chi-square."""
    return SetOutcome(
        o.time,
        r,
        ti,
        np.zeros((0, 3)),
        -1,
        0.0,
        np.full(7, np.nan),
        [],
        np.zeros(0),
        status="inconsistent",
        body_T_sensor=o.body_T_sensor.matrix(),
    )


def quats(poses: list) -> np.ndarray:
    """(K,4) x y z w of the poses' rotations."""
    out = np.zeros((len(poses), 4))
    for i, p in enumerate(poses):
        q = p.rotation().toQuaternion()
        out[i] = (q.x(), q.y(), q.z(), q.w())
    return out


def rows_of(observation) -> int:
    """The log rows a candidate set was made of: its marker pixels, else one (a `candidates`
    set, an ellipse)."""
    return len(observation.pixels.markers) if observation.pixels is not None else 1
