"""The covariance of a robust inter-robot registration (issue 16): the cluster-robust
sandwich of the point-to-plane fit (`cluster_covariance`), scaled and floored by the model that
`scripts/bench_fusion.py --real --calibrate` fits by maximum likelihood on calibration trials
(`calibrated_covariance`, RegistrationConfig.covariance_scale / covariance_floor)."""

from __future__ import annotations

import numpy as np

from graphloc.mapping.registration import RegistrationConfig


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
