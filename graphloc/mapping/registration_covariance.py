"""The covariance of a robust inter-robot registration (issue 16): the cluster-robust sandwich
of the estimate's per-point influences (`cluster_covariance`) -- the polish's two directions and
their midpoint (`polish_influence`), or the fine stage's one-way fit where no polish ran
(`least_squares_influence`) -- inflated along the directions the views hardly
constrain (`degeneracy_term`) and scaled, by the two parameters that
`scripts/bench_fusion.py --real --calibrate` fits by maximum likelihood on calibration trials
(`calibrated_covariance`, RegistrationConfig.covariance_scale and covariance_degeneracy);
`estimate_covariance` puts them together for
`graphloc.mapping.robust_registration.robust_register`."""

from __future__ import annotations

import gtsam
import numpy as np
import scipy.sparse

from graphloc.mapping.registration import RegistrationConfig, information_right
from graphloc.mapping.registration_index import NearestIndex


def cluster_covariance(influence: np.ndarray, points: np.ndarray, block: float) -> np.ndarray:
    """Cluster-robust covariance of an M-estimate over cubic blocks of side `block`: the sandwich
    B / (B - 1) sum_b psi_b psi_b^T, psi_b the sum of the (n,6) per-point influences over the
    points of block b (CR1; Liang & Zeger 1986, Cameron & Miller 2015): residuals of points that
    share normals, voxels and sensor error are correlated, so they are summed per cluster."""
    influence, points = np.asarray(influence, dtype=float), np.asarray(points, dtype=float)
    if influence.ndim != 2 or influence.shape[1] != 6 or points.shape != (len(influence), 3):
        raise ValueError(
            f"cluster_covariance: influence (n,6) and points (n,3) expected, got "
            f"{influence.shape}, {points.shape}"
        )
    label = block_labels(points, block)
    B = int(label.max()) + 1
    # per-cluster sums as one sparse (B, n) membership product (np.add.at is unbuffered)
    member = scipy.sparse.csr_matrix((np.ones(len(label)), (label, np.arange(len(label)))))
    G = member @ influence
    cov = B / max(B - 1, 1) * (G.T @ G)
    return 0.5 * (cov + cov.T)


def least_squares_influence(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(n,6) influence -H^-1 J_i^T r_i of each row on the Gauss-Newton step of
    sum_i (r_i + J_i xi)^2, H = J^T J; None when H is singular (fewer than 6 independent rows)."""
    J, r = np.asarray(J, dtype=float), np.asarray(r, dtype=float)
    H = J.T @ J
    if len(J) < 6 or np.linalg.matrix_rank(H) < 6:
        return None
    return -(J * r[:, None]) @ np.linalg.inv(H)  # H symmetric


def polish_influence(views, T: np.ndarray, cfg: RegistrationConfig):
    """Per-point influences (left perturbation Exp(xi) T, target frame) on the polish's estimate
    at T and the points they belong to (target frame), for `cluster_covariance`: each direction's
    Geman-McClure-weighted point-to-plane residuals within cfg.polish_distance (`views`: the
    polish's two cut clouds) give -H^-1 w_i J_i^T r_i, the target-onto-source one carried by
    -Ad_T, each counting one half as the polish's midpoint does. None when a direction has too few
    correspondences for its 6x6 system."""
    T = np.asarray(T, dtype=float)
    k = cfg.polish_kernel
    out, where = [], []
    for (c, other), M, back in zip(((0, 1), (1, 0)), (T, np.linalg.inv(T)), (False, True)):
        Q = np.asarray(views[other].points)
        p = np.asarray(views[c].points) @ M[:3, :3].T + M[:3, 3]
        idx, _ = NearestIndex(Q, cfg.polish_distance).nearest(p)
        has = idx >= 0
        p, n = p[has], np.asarray(views[other].normals)[idx[has]]
        r = np.einsum("ij,ij->i", p - Q[idx[has]], n)
        sw = np.sqrt(k) / (k + r * r)  # the square root of the kernel's weight
        psi = least_squares_influence(np.hstack([np.cross(p, n), n]) * sw[:, None], r * sw)
        if psi is None:
            return None
        if back:  # the target onto the source: Exp(-Ad_T xi_B), its points in the target frame
            psi = -psi @ gtsam.Pose3(T).AdjointMap().T
            p = p @ T[:3, :3].T + T[:3, 3]
        out.append(0.5 * psi)
        where.append(p)
    return np.vstack(out), np.vstack(where)


def block_labels(points: np.ndarray, block: float) -> np.ndarray:
    """Index 0..B-1 of the cube of side `block` (a grid from the origin) that holds each of the
    (n,3) points, B the number of occupied cubes."""
    cells = np.floor(np.asarray(points, dtype=float) / block).astype(np.int64)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 1
    _, label = np.unique(
        (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2], return_inverse=True
    )
    return label.reshape(-1)


def degeneracy_term(P: np.ndarray, H: np.ndarray, scale_m: float, min_conditioning: float):
    """The 6x6 term Q that `calibrated_covariance` adds to the sandwich P (both right
    perturbation, as H, the inliers' point-to-plane Hessian): with rotations in metres at
    scale_m (as the acceptance's conditioning weighs them, `robust_register` step 4, there in
    the left perturbation), D = diag(1 / scale_m I3, I3), and u_k, lambda_k the eigenvectors
    and eigenvalues of D H D,
    Q = D [sum_k (min_conditioning lambda_max / lambda_k) (u_k^T P~ u_k) u_k u_k^T] D with
    P~ = D^-1 P D^-1 (the covariance with rotations in metres): each of the Hessian's
    directions gets the sandwich's own variance along it, weighted by how near that direction's
    conditioning lambda_k / lambda_max comes to min_conditioning -- one at the acceptance's
    threshold, fading as the views constrain it."""
    P, H = np.asarray(P, dtype=float), np.asarray(H, dtype=float)
    if P.shape != (6, 6) or H.shape != (6, 6) or not scale_m > 0 or not min_conditioning >= 0:
        raise ValueError(
            f"degeneracy_term: P, H (6,6), scale_m > 0 and min_conditioning >= 0 expected, got "
            f"{P.shape}, {H.shape}, {scale_m}, {min_conditioning}"
        )
    if min_conditioning == 0:  # no direction is held near degenerate: no inflation
        return np.zeros((6, 6))
    d = np.array([1.0 / scale_m] * 3 + [1.0] * 3)
    lam, U = np.linalg.eigh(d[:, None] * H * d[None, :])
    if lam[0] <= 0:
        raise ValueError("degeneracy_term: the Hessian is singular (a direction is unconstrained)")
    var = np.einsum("ik,ij,jk->k", U, P / d[:, None] / d[None, :], U)
    Q = d[:, None] * ((U * (min_conditioning * lam[-1] / lam * var)) @ U.T) * d[None, :]
    return 0.5 * (Q + Q.T)


def calibrated_covariance(P: np.ndarray, Q: np.ndarray, cfg: RegistrationConfig) -> np.ndarray:
    """s (P + c Q) for the cluster-robust covariance P and its degeneracy term Q (both right
    perturbation), s = cfg.covariance_scale, c = cfg.covariance_degeneracy, fitted by maximum
    likelihood by `scripts/bench_fusion.py --real --calibrate` (why: docs/design_algorithms.md)."""
    out = cfg.covariance_scale * (
        np.asarray(P, dtype=float) + cfg.covariance_degeneracy * np.asarray(Q, dtype=float)
    )
    return 0.5 * (out + out.T)


def estimate_covariance(views, T: np.ndarray, fit, cfg: RegistrationConfig, scale_m: float, least):
    """The uncalibrated terms (P, Q) of `calibrated_covariance` (right perturbation) of a
    registration T: P the cluster-robust sandwich (`cluster_covariance`, cfg.covariance_block)
    of the per-point influences on the estimate made -- the polish's two directions and their
    midpoint (`polish_influence` of `views`, `graphloc.mapping.registration_stages.Polished.views`)
    or, where no polish round ran (views None), the one-way point-to-plane fit `fit` = (J, r,
    points) of the inliers (`least_squares_influence`; left perturbation, target frame) --
    carried to the right perturbation (`information_right`); Q its `degeneracy_term` along the
    inliers' Hessian J^T J, rotations at scale_m, `least` the acceptance's least conditioning.
    None when the influences leave the sandwich singular (too few correspondences, fewer
    clusters than axes)."""
    if views is not None:
        influence = polish_influence(views, T, cfg)
    else:
        psi = least_squares_influence(fit[0], fit[1])
        influence = None if psi is None else (psi, fit[2])
    if influence is None:
        return None
    cov_left = cluster_covariance(*influence, cfg.covariance_block)
    if np.linalg.cond(cov_left) > 1e12:
        return None
    P = np.linalg.inv(information_right(np.linalg.inv(cov_left), T))
    P = 0.5 * (P + P.T)
    return P, degeneracy_term(P, information_right(fit[0].T @ fit[0], T), scale_m, least)
