"""Three robots localized from mutual bearings (seed 000, section III-A "Three Robots
Localization Algorithm", the algorithm of Spletzer et al. 2001, its ref. [16]): the pixel of
robot j in robot i's image for the 6 ordered pairs, the cameras and the baseline |T_12| ->
poses of C2 and C3 in C1's frame, batched over N formations: interior angles from the bearings,
the law of sines, each robot's triangle aligned to robot 1's (Kabsch). Bad formations are a
status per row, never raised. The steps and checks: docs/design_algorithms.md, "Mutual bearings".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gtsam
import numpy as np

from graphloc.cameras import normalize_rows
from graphloc.config_schema import config_dataclass, setting

STATUS_OK = "ok"
STATUS_NO_BEARING = (
    "no_bearing"  # a pixel is NaN (no detection) or cannot be lifted by the camera model
)
STATUS_DEGENERATE = "degenerate_triangle"  # smallest interior angle < min_angle (collinear robots)
STATUS_INCONSISTENT = (
    "inconsistent_bearings"  # closure, misfit or relative tilt beyond the config limits
)


@config_dataclass
class MutualConfig:
    """min_angle [rad]: smallest usable interior angle.
    max_closure [rad]: largest accepted |theta_1 + theta_2 + theta_3 - pi|.
    max_misfit: largest accepted RMS residual of the triangle alignment, / mean side length.
    max_relative_tilt [rad]: largest accepted angle between the `up` axes of C1 and C_j;
      the default pi/2 rejects turned-over solutions (label swaps), see the module docstring.
    up: the camera-frame axis pointing up on a ground robot (+z for a ParaboloidOmniCamera,
      (0,-1,0) for an OpenCV pinhole looking sideways).
    planar: robots on a plane with their `up` axes vertical (setting of [16])."""

    min_angle: float = setting(math.radians(2.0), gt=0.0, lt=math.pi / 3)
    max_closure: float = setting(math.radians(5.0), gt=0.0, allow_inf_nan=True)
    max_misfit: float = setting(0.05, gt=0.0, allow_inf_nan=True)
    max_relative_tilt: float = setting(math.pi / 2, gt=0.0, le=math.pi)
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    planar: bool = False

    def __post_init__(self):
        up = np.asarray(self.up, dtype=float)
        if up.shape != (3,) or not np.isfinite(up).all() or np.linalg.norm(up) == 0:
            raise ValueError(f"MutualConfig.up must be a non-zero 3-vector, got {self.up}")
        object.__setattr__(self, "up", tuple(up / np.linalg.norm(up)))


@dataclass(frozen=True)
class ThreeRobotPoses:
    """N formations. R (N,3,3,3): R[n, j] = ^1R_{j+1}, rotation of camera C_{j+1} in C1's
    frame (R[n,0] = I); t (N,3,3): t[n, j] = position of C_{j+1} in C1's frame [m]
    (t[n,0] = 0); scale (N,): the baseline |T_12| that fixed the scale; sides (N,3): side
    lengths opposite robots 1,2,3 (|T_23|, |T_13|, |T_12|); angles (N,3): measured interior
    angles [rad]; closure (N,): sum(angles) - pi; misfit (N,): RMS residual of the triangle
    alignment / mean side (0 noise-free); condition (N,); status (N,): one of the
    STATUS_* codes ('ok', 'no_bearing', 'degenerate_triangle', 'inconsistent_bearings');
    explain(n) gives the numbers. Rows that are not 'ok' hold NaN poses and sides."""

    R: np.ndarray
    t: np.ndarray
    scale: np.ndarray
    sides: np.ndarray
    angles: np.ndarray
    closure: np.ndarray
    misfit: np.ndarray
    condition: np.ndarray
    status: np.ndarray

    def __len__(self) -> int:
        return len(self.status)

    @property
    def ok(self) -> np.ndarray:
        return self.status == STATUS_OK

    def explain(self, n: int) -> str:
        """One line: formation n's status with the numbers behind it."""
        angles = ", ".join(f"{math.degrees(a):.3g}" for a in self.angles[n])
        return (
            f"formation {n}: {self.status[n]} (interior angles [{angles}] deg, closure "
            f"{math.degrees(self.closure[n]):+.3g} deg, misfit {self.misfit[n]:.3g}, "
            f"condition {self.condition[n]:.3g})"
        )

    def relative(self, n: int, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        """(^iR_j, ^iT_j): pose of camera C_j in C_i's frame, robots numbered 1..3."""
        if self.status[n] != STATUS_OK:
            raise ValueError(self.explain(n))
        if {i, j} - {1, 2, 3}:
            raise ValueError(f"robots are numbered 1..3, got ({i}, {j})")
        Ri, ti, Rj, tj = self.R[n, i - 1], self.t[n, i - 1], self.R[n, j - 1], self.t[n, j - 1]
        return Ri.T @ Rj, Ri.T @ (tj - ti)

    def pose3(self, n: int, i: int, j: int) -> gtsam.Pose3:
        R, t = self.relative(n, i, j)
        return gtsam.Pose3(gtsam.Rot3(R), t)


def three_cameras(cameras) -> tuple:
    if hasattr(cameras, "pixel_to_bearing"):
        return (cameras,) * 3
    cameras = tuple(cameras)
    if len(cameras) != 3 or not all(hasattr(c, "pixel_to_bearing") for c in cameras):
        raise ValueError(
            f"cameras must be one camera model or a sequence of 3, got {len(cameras)} items"
        )
    return cameras


def _check_pixels(pixels) -> np.ndarray:
    pixels = np.asarray(pixels, dtype=float)
    if pixels.ndim != 4 or pixels.shape[1:] != (3, 3, 2):
        raise ValueError(
            f"pixels must have shape (N,3,3,2) (pixels[n,i,j] = robot j in robot i's image), "
            f"got {pixels.shape}"
        )
    return pixels


def _rigid_align(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched Kabsch: R (N,3,3), t (N,3) minimizing sum |target - (R source + t)|^2 for
    (N,K,3) point sets."""
    cs, ct = source.mean(axis=1), target.mean(axis=1)
    H = np.einsum("nki,nkj->nij", source - cs[:, None], target - ct[:, None])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", Vt, U)))  # det(V U^T)
    D = np.zeros_like(H)
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = np.where(d == 0, 1.0, d)
    R = np.einsum("nji,njk,nlk->nil", Vt, D, U)  # V D U^T
    return R, ct - np.einsum("nij,nj->ni", R, cs)


def localize_three(
    pixels, cameras, baseline_12, config: MutualConfig = MutualConfig()
) -> ThreeRobotPoses:
    """Relative poses of three mutually observing robots (module docstring, seed 000 III-A).

    pixels (N,3,3,2): pixels[n, i, j] = pixel of robot j in robot i's image (diagonal
      ignored). cameras: one camera model for all robots or a sequence of 3 (anything with
      pixel_to_bearing, e.g. graphloc.cameras.ParaboloidOmniCamera).
    baseline_12: |T_12| [m], a scalar or (N,) array, positive and finite.
    """
    pixels = _check_pixels(pixels)
    cams = three_cameras(cameras)
    N = len(pixels)
    # 1. bearings u[n, i, j] in frame i
    u = np.full((N, 3, 3, 3), np.nan)
    for i in range(3):
        others = [j for j in range(3) if j != i]
        b, v = cams[i].pixel_to_bearing(pixels[:, i, others].reshape(-1, 2))
        b = b.reshape(N, 2, 3)
        b[~v.reshape(N, 2)] = np.nan
        u[:, i, others] = b
    return localize_three_bearings(u, baseline_12, config)


def localize_three_bearings(
    bearings, baseline_12, config: MutualConfig = MutualConfig()
) -> ThreeRobotPoses:
    """`localize_three` from unit bearings instead of pixels: bearings (N,3,3,3),
    bearings[n, i, j] = direction of robot j in robot i's frame (diagonal ignored; NaN: not
    lifted); baseline_12 as there."""
    u = np.array(bearings, dtype=float)
    if u.ndim != 4 or u.shape[1:] != (3, 3, 3):
        raise ValueError(f"bearings must have shape (N, 3, 3, 3), got {u.shape}")
    N = len(u)
    baseline = (
        np.broadcast_to(np.asarray(baseline_12, dtype=float), (N,))
        if np.ndim(baseline_12) == 0
        else np.asarray(baseline_12, dtype=float)
    )
    if baseline.shape != (N,):
        raise ValueError(f"baseline_12 must be a scalar or shape ({N},), got {baseline.shape}")
    bad = np.flatnonzero(~(np.isfinite(baseline) & (baseline > 0)))
    if len(bad):
        raise ValueError(
            f"baseline_12 must be positive and finite; bad at formation(s) {bad[:5].tolist()}"
        )

    valid = np.isfinite(u).all(axis=-1)
    up = np.asarray(config.up)
    if config.planar:
        u = normalize_rows(u - (u @ up)[..., None] * up)
    status = np.full(N, STATUS_OK, dtype=object)
    lifted = valid & np.isfinite(u).all(axis=-1)
    off_diagonal = ~np.eye(3, dtype=bool)
    status[~(lifted | ~off_diagonal).all(axis=(1, 2))] = STATUS_NO_BEARING

    # 2. interior angles, closure
    idx = np.arange(3)
    nxt, prv = (idx + 1) % 3, (idx + 2) % 3
    cosines = np.einsum("nkc,nkc->nk", u[:, idx, nxt], u[:, idx, prv])
    angles = np.arccos(np.clip(cosines, -1.0, 1.0))
    closure = angles.sum(axis=1) - math.pi
    corrected = angles - closure[:, None] / 3.0
    with np.errstate(divide="ignore", invalid="ignore"):
        condition = 1.0 / np.sin(np.clip(corrected, 0.0, math.pi)).min(axis=1)
    ok = status == STATUS_OK
    status[ok & ~(corrected.min(axis=1) >= config.min_angle)] = STATUS_DEGENERATE
    ok = status == STATUS_OK
    status[ok & ~(np.abs(closure) <= config.max_closure)] = STATUS_INCONSISTENT
    ok = status == STATUS_OK

    # 3. law of sines; dist[n, i, j] = |T_ij|
    sin = np.sin(corrected)
    with np.errstate(divide="ignore", invalid="ignore"):
        sides = baseline[:, None] * sin / sin[:, 2:3]  # opposite robot 1, 2, 3
    dist = np.zeros((N, 3, 3))
    for i in range(3):  # the side between i and j is opposite the third robot k
        for j in range(3):
            if i != j:
                dist[:, i, j] = sides[:, 3 - i - j]

    # 4. triangle in each robot's frame, aligned to robot 1's
    vertices = dist[..., None] * np.nan_to_num(
        u
    )  # vertices[n, i, j] = robot j in frame i (0 for j == i)
    R = np.full((N, 3, 3, 3), np.nan)
    t = np.full((N, 3, 3), np.nan)
    misfit = np.full(N, np.nan)
    if ok.any():
        R[ok, 0], t[ok, 0] = np.eye(3), 0.0
        residual = np.zeros(ok.sum())
        upright = np.ones(ok.sum(), dtype=bool)
        for j in (1, 2):
            R[ok, j], t[ok, j] = _rigid_align(vertices[ok, j], vertices[ok, 0])
            aligned = np.einsum("nij,nkj->nki", R[ok, j], vertices[ok, j]) + t[ok, j][:, None]
            rms = np.sqrt(np.mean(np.sum((aligned - vertices[ok, 0]) ** 2, axis=2), axis=1))
            residual = np.maximum(residual, rms / sides[ok].mean(axis=1))
            upright &= up @ R[ok, j] @ up >= math.cos(config.max_relative_tilt) - 1e-12
        misfit[ok] = residual
        bad = np.flatnonzero(ok)[~((residual <= config.max_misfit) & upright)]
        status[bad] = STATUS_INCONSISTENT
        R[bad], t[bad] = np.nan, np.nan
        ok = status == STATUS_OK
    sides[~ok] = np.nan
    return ThreeRobotPoses(
        R, t, baseline.copy(), sides, angles, closure, misfit, condition, status.astype(str)
    )
