"""The covariance of a robust inter-robot registration (issue 16): the leave-one-cluster-out
jackknife of the point-to-plane fit (`cluster_covariance`), scaled by the one parameter that
`scripts/bench_fusion.py --real --calibrate` fits by maximum likelihood on calibration trials
(`calibrated_covariance`, RegistrationConfig.covariance_scale)."""

from __future__ import annotations

import numpy as np
import scipy.sparse

from graphloc.mapping.registration import RegistrationConfig


def cluster_covariance(
    J: np.ndarray, r: np.ndarray, points: np.ndarray, H: np.ndarray, block: float
) -> np.ndarray:
    """Cluster-robust covariance of the least-squares pose by the leave-one-cluster-out
    jackknife over cubic blocks of side `block` (CR3: (B - 1) / B sum_b d_b d_b^T with
    d_b = (H - H_b)^-1 g_b, g_b = sum_{i in b} J_i^T r_i, H_b = sum_{i in b} J_i^T J_i;
    Bell & McCaffrey 2002, MacKinnon & White 1985). Residuals of points that share normals,
    voxels and sensor error are correlated, so they are summed per cluster (Liang & Zeger 1986);
    the plain sandwich H^-1 (sum_b g_b g_b^T) H^-1 is biased low when a registration has few
    clusters or clusters of high leverage (a partial overlap holds a few dozen blocks, and one wall
    may carry most of a direction): dropping cluster b moves the estimate by d_b, so a cluster that
    constrains a direction alone inflates that direction. A cluster without which H is singular
    (it alone constrains a direction) gets its shift through the pseudo-inverse."""
    J, r, points, H = (np.asarray(a, dtype=float) for a in (J, r, points, H))
    if len(J) != len(r) or len(J) != len(points) or J.shape[1:] != (6,) or H.shape != (6, 6):
        raise ValueError(
            f"cluster_covariance: J (n,6), r (n,), points (n,3) and H (6,6) expected, got "
            f"{J.shape}, {r.shape}, {points.shape}, {H.shape}"
        )
    label = block_labels(points, block)
    B = int(label.max()) + 1
    # per-cluster sums as one sparse (B, n) membership product (np.add.at is unbuffered)
    member = scipy.sparse.csr_matrix((np.ones(len(label)), (label, np.arange(len(label)))))
    G = member @ (J * r[:, None])
    Hb = (member @ (J[:, :, None] * J[:, None, :]).reshape(-1, 36)).reshape(B, 6, 6)
    rest = H[None] - Hb
    d = np.einsum("bij,bj->bi", np.linalg.pinv(rest, hermitian=True), G)
    cov = (B - 1) / max(B, 1) * (d.T @ d)
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
    """s P for the jackknife covariance P (right perturbation), s = cfg.covariance_scale. P sees
    the residual noise, its correlation within a cluster and each cluster's leverage; it cannot
    see what the fit absorbs -- surfaces sampled differently in the two scans, normals smoothed
    over the normal radius, correspondences re-chosen as the pose moves -- which shows as errors
    larger than P in every direction. s is fitted by maximum likelihood, e_i ~ N(0, s P_i), on
    calibration trials by `scripts/bench_fusion.py --real --calibrate`; the benchmark checks the
    NEES on other trials."""
    out = cfg.covariance_scale * np.asarray(cov, dtype=float)
    return 0.5 * (out + out.T)
