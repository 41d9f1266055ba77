"""First-order covariance of a camera pose recovered by P3P / resection from pixel noise
(the candidate covariance every P3P front-end hands to the engines: seed 000 Sec. V, seed 004
Sec. II-C -- the P3P candidates' uncertainty that the belief vector and particle filter ignore)."""

from __future__ import annotations

import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.geometry.so3 import skew


def resection_covariance(
    camera: PinholeCamera,
    R_wc: np.ndarray,
    t_wc: np.ndarray,
    points: np.ndarray,
    pixel_sigma: float,
    floor: tuple[float, float] = (1e-3, 1e-3),
) -> np.ndarray:
    """First-order covariance (N,6,6) of camera poses (N,3,3)/(N,3) recovered from the pixels of
    M >= 3 world points (N,M,3) with isotropic pixel noise: sigma^2 (A^T A)^-1, A (2M x 6) =
    d pixels / d pose (GTSAM Pose3 tangent (rot, trans), right perturbation T Exp(xi)). With
    three points (P3P) the problem is square (6 pixel coordinates, 6 pose DOF), so A is
    invertible away from the danger cylinder and blows up near it. A camera with lens
    distortion: A by central differences through `camera.project`. `floor` = (rad, m) sigmas
    added on the diagonal."""
    R_wc, t_wc, points = (np.asarray(a, dtype=float) for a in (R_wc, t_wc, points))
    n = len(R_wc)
    if (
        R_wc.shape != (n, 3, 3)
        or t_wc.shape != (n, 3)
        or points.ndim != 3
        or points.shape[0] != n
        or points.shape[1] < 3
        or points.shape[2] != 3
    ):
        raise ValueError(
            f"resection_covariance: expected R_wc (N,3,3), t_wc (N,3), points (N,M>=3,3); got "
            f"{R_wc.shape}, {t_wc.shape}, {points.shape}"
        )
    if not (np.isfinite(pixel_sigma) and pixel_sigma >= 0):
        raise ValueError(
            f"resection_covariance: pixel_sigma must be finite >= 0, got {pixel_sigma}"
        )
    m = points.shape[1]
    pc = np.einsum("nji,npj->npi", R_wc, points - t_wc[:, None, :])  # (N,M,3) camera-frame points
    hat = skew(pc)  # d(pc)/d(rotation) for the right perturbation
    dpc = np.concatenate([hat, np.broadcast_to(-np.eye(3), hat.shape)], axis=-1)  # (N,M,3,6)
    if any(camera.dist):
        J = _projection_jacobian(camera, pc)
    else:
        x, y, z = pc[..., 0], pc[..., 1], pc[..., 2]
        J = np.zeros(pc.shape[:2] + (2, 3))  # d(uv)/d(pc)
        J[..., 0, 0], J[..., 0, 2] = camera.fx / z, -camera.fx * x / z**2
        J[..., 1, 1], J[..., 1, 2] = camera.fy / z, -camera.fy * y / z**2
    A = (J @ dpc).reshape(n, 2 * m, 6)
    cov = pixel_sigma**2 * np.linalg.pinv(np.einsum("nki,nkj->nij", A, A), hermitian=True)
    cov += np.diag(np.repeat(np.square(floor), 3))
    return 0.5 * (cov + np.transpose(cov, (0, 2, 1)))


def _projection_jacobian(camera: PinholeCamera, pc: np.ndarray) -> np.ndarray:
    """d(pixel)/d(camera-frame point) (..., 2, 3) of a distorted camera by central differences
    (a step of 1e-6 of each point's depth)."""
    flat = pc.reshape(-1, 3)
    h = 1e-6 * np.maximum(np.abs(flat[:, 2]), 1e-3)
    J = np.zeros((len(flat), 2, 3))
    for a in range(3):
        step = np.zeros_like(flat)
        step[:, a] = h
        plus, _ = camera.project(flat + step)
        minus, _ = camera.project(flat - step)
        J[:, :, a] = (plus - minus) / (2 * h[:, None])
    return J.reshape(pc.shape[:-1] + (2, 3))
