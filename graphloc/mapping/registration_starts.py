"""Where `graphloc.mapping.robust_registration.robust_register` starts ICP (issue 16): the pose
hint (`checked_hint`) and the sigma points of its covariance (`hint_starts`, `hint_covariance`),
and, once the polish has carried the view beyond the fine stage's reach of the candidate it
polished, the two poses as far either way along the estimate's least constrained direction
(`weak_direction_starts`), and, when the only candidates left are slid views, the two poses
the hint's reach either way along a slid view's own (`escape_starts`)."""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.mapping.registration import information_right


def checked_hint(hint, hint_cov) -> tuple[np.ndarray, np.ndarray]:
    """`robust_register`'s pose hint (a finite 4x4 transform) and its covariance (a finite 6x6
    positive definite matrix) as float arrays; ValueError naming the one that is not."""
    hint, hint_cov = np.asarray(hint, dtype=float), np.asarray(hint_cov, dtype=float)
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
    return hint, hint_cov


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


def weak_direction_starts(
    T: np.ndarray, cov: np.ndarray, reach: float, step: float
) -> list[np.ndarray]:
    """T Exp(+-xi): xi along the eigenvector of the largest eigenvalue of D cov D (cov: T's 6x6
    right-perturbation covariance, rot [rad] then trans [m]; D scales the rotations by `reach`
    [m], the median range of the view's points, so that both parts are metres those points
    move), of length `step` [m] in that scaled norm. Where a floor-dominated view can slide or
    turn to a second minimum that fits about as well, these are the starts that find it."""
    D = np.diag([reach] * 3 + [1.0] * 3)
    _, V = np.linalg.eigh(D @ (0.5 * (cov + cov.T)) @ D)
    xi = np.linalg.solve(D, V[:, -1]) * step
    T = np.asarray(T, dtype=float)
    return [T @ gtsam.Pose3.Expmap(sign * xi).matrix() for sign in (1.0, -1.0)]


def escape_starts(T: np.ndarray, J: np.ndarray, reach: float, step: float) -> list[np.ndarray]:
    """`weak_direction_starts` of a slid view at T: its covariance the inverse of the
    point-to-plane Hessian J^T J of its inliers' Jacobian rows J (n,6) (left perturbation,
    `graphloc.mapping.acceptance.point_to_plane`), carried to the right perturbation
    (`information_right`); `step` [m] the hint's reach. A view slid along a dominant plane into a
    local minimum lies in a valley whose floor is that direction; the pose lies along it, a
    distance the hint's uncertainty allows. No starts when the rows leave the Hessian singular."""
    J = np.asarray(J, dtype=float)
    H = information_right(J.T @ J, T) if len(J) >= 6 else np.zeros((6, 6))
    lam = np.linalg.eigvalsh(H)
    if lam[0] <= 1e-12 * max(lam[-1], 0.0):  # singular to double precision
        return []
    return weak_direction_starts(T, np.linalg.inv(H), reach, step)
