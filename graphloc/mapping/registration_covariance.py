"""The covariance of a robust inter-robot registration (issue 16): the cluster-robust sandwich
of the point-to-plane fit (`cluster_covariance`), scaled by the one parameter that
`scripts/bench_fusion.py --real --calibrate` fits by maximum likelihood on calibration trials
(`calibrated_covariance`, RegistrationConfig.covariance_scale)."""

from __future__ import annotations

import numpy as np
import scipy.sparse

from graphloc.mapping.registration import RegistrationConfig


def cluster_covariance(
    J: np.ndarray, r: np.ndarray, points: np.ndarray, H: np.ndarray, block: float
) -> np.ndarray:
    """Cluster-robust covariance of the least-squares pose over cubic blocks of side `block`:
    the sandwich B / (B - 1) H^-1 (sum_b g_b g_b^T) H^-1 with g_b = sum_{i in b} J_i^T r_i, the
    score of cluster b (CR1; Liang & Zeger 1986, with the small-sample factor of Cameron &
    Miller 2015). Residuals of points that share normals, voxels and sensor error are correlated,
    so they are summed per cluster; blocks a few normal radii wide hold that correlation and
    leave a registration enough clusters for the sum. The leave-one-cluster-out jackknife (CR3)
    inflates a direction that one cluster constrains alone by (H - H_b)^-1: on a small overlap of
    a real room (the Redwood fragment at 30%, exploration seeds 200-229) its sigmas stood several
    times above the errors in the very directions the sandwich's followed them."""
    J, r, points, H = (np.asarray(a, dtype=float) for a in (J, r, points, H))
    if len(J) != len(r) or len(J) != len(points) or J.shape[1:] != (6,) or H.shape != (6, 6):
        raise ValueError(
            f"cluster_covariance: J (n,6), r (n,), points (n,3) and H (6,6) expected, got "
            f"{J.shape}, {r.shape}, {points.shape}, {H.shape}"
        )
    label = block_labels(points, block)
    B = int(label.max()) + 1
    # per-cluster scores as one sparse (B, n) membership product (np.add.at is unbuffered)
    member = scipy.sparse.csr_matrix((np.ones(len(label)), (label, np.arange(len(label)))))
    G = member @ (J * r[:, None])
    H_inv = np.linalg.inv(H)
    cov = B / max(B - 1, 1) * (H_inv @ (G.T @ G) @ H_inv)
    return 0.5 * (cov + cov.T)


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


def calibrated_covariance(cov: np.ndarray, cfg: RegistrationConfig) -> np.ndarray:
    """s P for the cluster-robust covariance P (right perturbation), s = cfg.covariance_scale. P
    sees the residual noise and its correlation within a cluster; it cannot
    see what the fit absorbs -- surfaces sampled differently in the two scans, normals smoothed
    over the normal radius, correspondences re-chosen as the pose moves -- which shows as errors
    larger than P in every direction. s is fitted by maximum likelihood, e_i ~ N(0, s P_i), on
    calibration trials by `scripts/bench_fusion.py --real --calibrate`; the benchmark checks the
    NEES on other trials."""
    out = cfg.covariance_scale * np.asarray(cov, dtype=float)
    return 0.5 * (out + out.T)
