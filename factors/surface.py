"""Surface constraint (seed 000 Sec. I-A, VI-B; seed 004 Algorithm 1 line 7): a climbing robot
stays on a known plane within a thickness sigma (gtsam.PoseTranslationPrior3D with a rank-1
square-root information n^T / sigma), its body axis normal to the surface aligned with the
plane normal (gtsam.AttitudeFactorPose3).
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np


@dataclass(frozen=True)
class SurfacePlane:
    """Plane through `point` (3,) with unit `normal` (3,) (world frame)."""

    point: np.ndarray
    normal: np.ndarray

    def __post_init__(self):
        p = np.asarray(self.point, dtype=float)
        n = np.asarray(self.normal, dtype=float)
        if (
            p.shape != (3,)
            or n.shape != (3,)
            or not (np.isfinite(p).all() and np.isfinite(n).all())
        ):
            raise ValueError(
                "SurfacePlane: point and normal must be finite 3-vectors, "
                f"got {self.point!r}, {self.normal!r}"
            )
        norm = np.linalg.norm(n)
        if norm < 1e-12:
            raise ValueError("SurfacePlane: normal must be non-zero")
        object.__setattr__(self, "point", p)
        object.__setattr__(self, "normal", n / norm)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distances (N,) of points (N,3) along the normal."""
        return (np.asarray(points, dtype=float) - self.point) @ self.normal

    @classmethod
    def sloped_ceiling(cls) -> "SurfacePlane":
        """Seed 000 ceiling II: 45 deg, from 2 m at x = 0 to 5 m at x = 3 (z = 2 + x)."""
        return cls(np.array([0.0, 0.0, 2.0]), np.array([1.0, 0.0, -1.0]))

    @classmethod
    def floor(cls) -> "SurfacePlane":
        return cls(np.zeros(3), np.array([0.0, 0.0, 1.0]))


def plane_distance_factor(
    key: int, plane: SurfacePlane, sigma: float
) -> gtsam.PoseTranslationPrior3D:
    """The pose's translation stays within `sigma` [m] of the plane (free along it)."""
    sigma = float(sigma)
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"plane_distance_factor: sigma must be finite > 0, got {sigma}")
    R = np.zeros((3, 3))
    R[0] = plane.normal / sigma
    return gtsam.PoseTranslationPrior3D(
        key, plane.point, gtsam.noiseModel.Gaussian.SqrtInformation(R)
    )


def plane_attitude_factor(
    key: int, plane: SurfacePlane, sigma: float, body_normal=(0.0, 0.0, 1.0)
) -> gtsam.AttitudeFactorPose3:
    """The body axis `body_normal` stays along the plane normal within `sigma` [rad]."""
    sigma = float(sigma)
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"plane_attitude_factor: sigma must be finite > 0, got {sigma}")
    b = np.asarray(body_normal, dtype=float)
    if b.shape != (3,) or not np.isfinite(b).all() or np.linalg.norm(b) < 1e-12:
        raise ValueError(
            f"plane_attitude_factor: body_normal must be a non-zero 3-vector, got {body_normal!r}"
        )
    return gtsam.AttitudeFactorPose3(
        key,
        gtsam.Unit3(plane.normal),
        gtsam.noiseModel.Isotropic.Sigma(2, sigma),
        gtsam.Unit3(b / np.linalg.norm(b)),
    )
