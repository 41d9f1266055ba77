"""Batched Pose3 maps in GTSAM's conventions, in NumPy, for the HypothesisTracker's per-frame
work: `log` (Pose3.Logmap, with `jacobian=True` also LogmapDerivative Jr^-1 and ad(xi)), `exp`
(Pose3.Expmap, homogeneous 4x4), `inverse_right_jacobian`; tangent order (omega, v), right
perturbation. Jr^-1(xi) = f(ad_xi), f(x) = x / (1 - e^-x) (Barfoot and Furgale 2014, eq. 100ff);
the series and closed forms: docs/design_algorithms.md, "Pose3 maps"."""

from __future__ import annotations

from fractions import Fraction
from math import factorial

import gtsam
import numpy as np

# x @ _SKEW -> the flattened 3x3 skew matrix [x]_x
_SKEW = np.zeros((3, 9))
for _row, _col, _sign in ((2, 1, -1), (1, 2, 1), (2, 3, 1), (0, 5, -1), (1, 6, -1), (0, 7, 1)):
    _SKEW[_row, _col] = _sign
# xi @ _AD -> the flattened 6x6 ad(xi) = [[W, 0], [V, W]] (W = [omega]_x, V = [v]_x)
_AD = np.zeros((6, 36))
for _row, _col, _sign in zip(*np.nonzero(_SKEW), _SKEW[np.nonzero(_SKEW)]):
    i, j = divmod(int(_col), 3)
    _AD[_row, 6 * i + j] = _AD[_row, 6 * (i + 3) + j + 3] = _sign  # both W blocks
    _AD[_row + 3, 6 * (i + 3) + j] = _sign  # V block
# xi @ _HAT -> the flattened 4x4 twist matrix [[W, v], [0, 0]]
_HAT = np.zeros((6, 16))
for _row, _col in zip(*np.nonzero(_SKEW)):
    _HAT[_row, 4 * (_col // 3) + _col % 3] = _SKEW[_row, _col]
_HAT[[3, 4, 5], [3, 7, 11]] = 1.0
_I3, _I4, _I6 = np.eye(3), np.eye(4), np.eye(6)
# flattened R @ _VEE_TRACE: R[2,1] - R[1,2], R[0,2] - R[2,0], R[1,0] - R[0,1] (2 sin(theta)
# axis) and the trace
_VEE_TRACE = np.zeros((9, 4))
for _col, (_plus, _minus) in enumerate(((7, 5), (2, 6), (3, 1))):
    _VEE_TRACE[_plus, _col], _VEE_TRACE[_minus, _col] = 1.0, -1.0
_VEE_TRACE[[0, 4, 8], 3] = 1.0
_NEAR_PI = 1e-3  # Rot3::Logmap's special case: tr R + 1 below this
_SERIES_MAX = 1.0  # [rad] power series below, closed forms above

# Bernoulli numbers B_0, B_2, ..., B_22 (x/2 coth(x/2) = sum B_2k x^2k / (2k)!)
_B2K = [Fraction(1), Fraction(1, 6), Fraction(-1, 30), Fraction(1, 42), Fraction(-1, 30)]
_B2K += [Fraction(5, 66), Fraction(-691, 2730), Fraction(7, 6), Fraction(-3617, 510)]
_B2K += [Fraction(43867, 798), Fraction(-174611, 330), Fraction(854513, 138)]
_TERMS = 10  # powers of theta^2 kept: the series' radius is 2 pi, below 1 rad ~1e-16


def _log_series() -> np.ndarray:
    """(_TERMS, 3) coefficients of theta^2k in c, alpha, beta (module docstring):
    g = (theta/2) cot(theta/2) = sum (-1)^k B_2k theta^2k / (2k)!, c = (1 - g) / theta^2,
    g' = d/dmu (sqrt(mu)/2 coth(sqrt(mu)/2)) at mu = -theta^2, alpha = 2c - g',
    beta = (c - g') / theta^2."""
    n = _TERMS + 2
    b = [_B2K[k] / factorial(2 * k) for k in range(n)]
    c = [-((-1) ** k) * b[k] for k in range(1, n)]  # theta^(2k-2)
    gp = [k * b[k] * (-1) ** (k - 1) for k in range(1, n)]
    alpha = [2 * x - y for x, y in zip(c, gp)]
    beta = [x - y for x, y in zip(c, gp)][1:]  # the theta^0 term is 0
    return np.array([[float(s[k]) for s in (c, alpha, beta)] for k in range(_TERMS)])


def _exp_series() -> np.ndarray:
    """(_TERMS, 2) coefficients of theta^2k in (1 - cos t)/t^2 and (t - sin t)/t^3."""
    return np.array([[(-1) ** k / factorial(2 * k + m) for m in (2, 3)] for k in range(_TERMS)])


_LOG_SERIES, _EXP_SERIES = _log_series(), _exp_series()
_POWERS = np.arange(_TERMS, dtype=float)
# the reductions without ndarray methods' Python wrappers (called per pose batch)
_sum, _min, _max = np.add.reduce, np.minimum.reduce, np.maximum.reduce


def _log_coefficients(theta: np.ndarray) -> np.ndarray:
    """(N,3): c, alpha, beta of the module docstring at rotation angles theta (N,)."""
    coef = (theta * theta)[:, None] ** _POWERS @ _LOG_SERIES
    if _max(theta) >= _SERIES_MAX:
        big = theta >= _SERIES_MAX
        th = theta[big]
        half = 0.5 * th
        cot = 1.0 / np.tan(half)
        c = (1.0 - half * cot) / th**2
        gp = 0.125 / np.sin(half) ** 2 - 0.25 * cot / th
        coef[big] = np.stack([c, 2.0 * c - gp, (c - gp) / th**2], axis=1)
    return coef


def _exp_coefficients(theta: np.ndarray) -> np.ndarray:
    """(N,2): b = (1 - cos t)/t^2, c = (t - sin t)/t^3 at angles theta (N,)."""
    coef = (theta * theta)[:, None] ** _POWERS @ _EXP_SERIES
    if _max(theta) >= _SERIES_MAX:
        big = theta >= _SERIES_MAX
        th = theta[big]
        coef[big] = np.stack([(1.0 - np.cos(th)) / th**2, (th - np.sin(th)) / th**3], axis=1)
    return coef


def skew(w: np.ndarray) -> np.ndarray:
    """(N,3) -> (N,3,3) skew-symmetric matrices, [w]_x x = w x x."""
    return (w @ _SKEW).reshape(-1, 3, 3)


def adjoint(xi: np.ndarray) -> np.ndarray:
    """(N,6) -> (N,6,6) ad(xi) (gtsam.Pose3.adjointMap)."""
    return (xi @ _AD).reshape(-1, 6, 6)


def so3_log(R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation vectors (N,3) and angles (N,) of rotation matrices (N,3,3) (Rot3::Logmap)."""
    q = R.reshape(-1, 9) @ _VEE_TRACE
    vee, tr = q[:, :3], q[:, 3]  # 2 sin(theta) axis, 1 + 2 cos(theta)
    s = np.sqrt(_sum(vee * vee, 1))
    theta = np.arctan2(s, tr - 1.0)
    w = vee * (theta / np.maximum(s, 1e-300))[:, None]
    if _min(tr) < _NEAR_PI - 1.0:
        for i in np.flatnonzero(tr < _NEAR_PI - 1.0):
            w[i] = gtsam.Rot3.Logmap(gtsam.Rot3(R[i]))
        theta = np.sqrt(_sum(w * w, 1))
    return w, theta


def log(R: np.ndarray, t: np.ndarray, jacobian: bool = False):
    """gtsam.Pose3.Logmap of the poses (R (N,3,3), t (N,3)), N >= 1 -> xi (N,6); with
    `jacobian` also (Jr^-1 (N,6,6), ad(xi) (N,6,6))."""
    w, theta = so3_log(R)
    coef = _log_coefficients(theta)[:, :, None, None]
    W = skew(w)
    u = ((_I3 - 0.5 * W + coef[:, 0] * (W @ W)) @ t[:, :, None])[:, :, 0]  # V^-1 t
    xi = np.concatenate([w, u], axis=1)
    if not jacobian:
        return xi
    ad = adjoint(xi)
    return xi, _inverse_right_jacobian(ad, coef), ad


def _inverse_right_jacobian(ad: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """I + ad / 2 + ad^2 (alpha I + beta ad^2); coef (N,3,1,1): c, alpha, beta."""
    ad2 = ad @ ad
    return _I6 + 0.5 * ad + ad2 @ (coef[:, 1] * _I6 + coef[:, 2] * ad2)


def inverse_right_jacobian(xi: np.ndarray) -> np.ndarray:
    """gtsam.Pose3.LogmapDerivative at tangent vectors xi (N,6), N >= 1 -> (N,6,6)."""
    theta = np.sqrt(_sum(xi[:, :3] * xi[:, :3], 1))
    return _inverse_right_jacobian(adjoint(xi), _log_coefficients(theta)[:, :, None, None])


def exp(xi: np.ndarray) -> np.ndarray:
    """gtsam.Pose3.Expmap of tangent vectors xi (N,6), N >= 1 -> homogeneous (N,4,4):
    I + X + X^2 (b I + c X) for the twist matrix X = [[W, v], [0, 0]] (X^3 = -theta^2 X on the
    rotation block: R = I + a W + b W^2, t = (I + b W + c W^2) v)."""
    X = (xi @ _HAT).reshape(-1, 4, 4)
    theta = np.sqrt(_sum(xi[:, :3] * xi[:, :3], 1))
    coef = _exp_coefficients(theta)[:, :, None, None]
    return _I4 + X + (X @ X) @ (coef[:, 0] * _I4 + coef[:, 1] * X)
