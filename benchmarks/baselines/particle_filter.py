"""Seed 004 (004_fa12d1d18dcbd0db.txt) Sec. II-C: particle filter over the P3P solutions.

Prior (II-C.1): the m solutions of the first frame are particles of weight 1/m. Prediction
(II-C.2/3, Algorithm 1, odometry sample motion model): the odometry step, expressed in the
motion plane, gives heading delta_theta = atan2(dy, dx) and length delta_T = hypot(dx, dy);
both get a zero-mean Gaussian sample of std alpha1 |delta_theta| + alpha2 delta_T; the particle
moves by (delta_T' cos delta_theta', delta_T' sin delta_theta') in the plane and keeps its
offset along the plane normal (line 7, z' = z). Update (II-C.4, eq. 3): importance weight =
RBF kernel exp(-|z_n - x_m|^2 / 2 sigma^2) to the nearest new solution z_n. Algorithm 2 line 5
merges weights additively (w_t = w_{t-1} + w_bar), then normalizes; line 8 picks the particle
of maximum weight. Each particle then continues from its nearest new solution.

The odometry (camera frame of the previous pose) is rotated into the world by each particle's
own rotation; the plane is given by its world normal (`plane_normal`; seed 004: the ceiling).
Commit / relocate use the same threshold rule as the other engines so that comparisons agree.
"""

from __future__ import annotations


import gtsam
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from graphloc.candidates import CandidateSet
from graphloc.seams import Decision, Odometry, check_frame


@config_dataclass
class ParticleFilterConfig:
    """alpha1 [rad/rad], alpha2 [1]: Algorithm 1 noise; sigma [m]: RBF width of eq. (3)
    (not given in the seed); plane_normal: world normal of the motion plane; threshold: commit."""

    alpha1: float = setting(0.01, ge=0.0)
    alpha2: float = setting(0.15, ge=0.0)
    sigma: float = setting(0.05, gt=0.0)
    plane_normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    threshold: float = setting(0.95, gt=0.0, lt=1.0)
    seed: int = 0

    def __post_init__(self):
        n = np.asarray(self.plane_normal, dtype=float)
        if n.shape != (3,) or not np.isfinite(n).all() or np.linalg.norm(n) < 1e-9:
            raise ValueError(
                "ParticleFilterConfig.plane_normal must be a non-zero 3-vector, "
                f"got {self.plane_normal}"
            )


def plane_basis(normal) -> np.ndarray:
    """(3,3) rows e1, e2, n: an orthonormal basis with n the unit plane normal."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(n, helper)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(n, e1), n])


def sample_motion(
    positions: np.ndarray,
    steps_world: np.ndarray,
    basis: np.ndarray,
    alpha1: float,
    alpha2: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Algorithm 1 of seed 004 for M particles at once: positions (M,3), odometry steps in the
    world (M,3) -> sampled new positions (M,3)."""
    local = steps_world @ basis.T  # (M,3): in-plane (dx, dy), normal component
    theta = np.arctan2(local[:, 1], local[:, 0])
    length = np.hypot(local[:, 0], local[:, 1])
    std = alpha1 * np.abs(theta) + alpha2 * length
    theta_s = theta + std * rng.standard_normal(len(theta))
    length_s = length + std * rng.standard_normal(len(theta))
    return (
        positions
        + (length_s * np.cos(theta_s))[:, None] * basis[0]
        + (length_s * np.sin(theta_s))[:, None] * basis[1]
    )


class ParticleFilter:
    """update(candidates, odometry) -> Decision, the same interface as HypothesisTracker."""

    def __init__(self, config: ParticleFilterConfig = ParticleFilterConfig()):
        self.config = config
        self._basis = plane_basis(config.plane_normal)
        self._rng = np.random.default_rng(config.seed)
        self._R = np.zeros((0, 3, 3))
        self._t = np.zeros((0, 3))
        self._w = np.zeros(0)
        self._assigned = np.zeros(0, dtype=int)
        self._committed: int | None = None
        self._last_time: float | None = None

    def update(self, candidates: CandidateSet, odometry: Odometry | None = None) -> Decision:
        cfg = self.config
        check_frame(
            candidates, odometry, self._last_time is None, self._last_time, "ParticleFilter.update"
        )
        self._last_time = candidates.time
        relocalized = False
        if len(self._w) and len(candidates) and odometry is not None:
            steps = self._R @ odometry.relative.translation()
            predicted = sample_motion(
                self._t, steps, self._basis, cfg.alpha1, cfg.alpha2, self._rng
            )
            d2 = np.sum((predicted[:, None, :] - candidates.t[None, :, :]) ** 2, axis=2)
            nn = np.argmin(d2, axis=1)
            w_bar = np.exp(-d2[np.arange(len(nn)), nn] / (2.0 * cfg.sigma**2))
            w = self._w + w_bar  # Algorithm 2 line 5 (merge), line 6 (normalize)
            self._w = w / w.sum()
            self._R, self._t, self._assigned = candidates.R[nn], candidates.t[nn], nn
        elif not len(self._w) or not len(candidates):  # prior (II-C.1), also after an empty frame
            relocalized = self._committed is not None
            self._committed = None
            self._R, self._t = candidates.R.copy(), candidates.t.copy()
            self._w = np.full(len(candidates), 1.0 / max(len(candidates), 1))
            self._assigned = np.arange(len(candidates))
        probs = np.zeros(len(candidates))
        np.add.at(probs, self._assigned, self._w)
        if self._committed is not None and probs[self._assigned[self._committed]] <= cfg.threshold:
            self._committed, relocalized = None, True
        if self._committed is None and len(probs) and probs.max() > cfg.threshold:
            self._committed = int(np.argmax(self._w))
        if not len(self._w):
            return Decision(probs, -1, False, None, relocalized)
        best = self._committed if self._committed is not None else int(np.argmax(self._w))  # line 8
        pose = gtsam.Pose3(gtsam.Rot3(self._R[best]), self._t[best])
        committed = int(self._assigned[self._committed]) if self._committed is not None else -1
        return Decision(probs, committed, self._committed is not None, pose, relocalized)
