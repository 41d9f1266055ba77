"""Ellipses in images (seed 003, section II-A "Robot Tracker", 1): the least-squares ellipse
fit to edge points (OpenCV: cv2.fitEllipseDirect, Fitzgibbon's direct least squares, the
seed's "least-squares fitting technique [3]"; AMS / plain fitEllipse selectable), the conic
of an ellipse and the Sampson distance to it, and the sub-pixel refinement of an ellipse by
an edge-model fit to a coverage map. The circle poses from these ellipses (seed eqs. (1)-(4))
are `graphloc.vision.circle`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.special import erfc

from graphloc.vision.images import check_points, opencv_errors

FITTERS = {"direct": cv2.fitEllipseDirect, "ams": cv2.fitEllipseAMS, "lsq": cv2.fitEllipse}


def ellipse_to_conic(ellipses: np.ndarray) -> np.ndarray:
    """(N,5) ellipses (u0, v0, width, height, angle deg; OpenCV RotatedRect) -> (N,3,3)
    symmetric conics C with [u v 1] C [u v 1]^T = 0 on the ellipse, < 0 inside."""
    e = np.asarray(ellipses, dtype=float).reshape(-1, 5)
    centre, a, b, ang = e[:, :2], e[:, 2] / 2.0, e[:, 3] / 2.0, np.radians(e[:, 4])
    c, s = np.cos(ang), np.sin(ang)
    axes = np.stack(
        [np.stack([c, s], -1), np.stack([-s, c], -1)], axis=2
    )  # columns: width / height axes
    with np.errstate(divide="ignore", invalid="ignore"):
        A = np.einsum("nij,nj,nkj->nik", axes, np.stack([1 / a**2, 1 / b**2], -1), axes)
    Ac = np.einsum("nij,nj->ni", A, centre)
    C = np.zeros((len(e), 3, 3))
    C[:, :2, :2] = A
    C[:, :2, 2] = C[:, 2, :2] = -Ac
    C[:, 2, 2] = np.einsum("ni,ni->n", centre, Ac) - 1.0
    return C


def sampson_rms(conic: np.ndarray, points: np.ndarray) -> float:
    """RMS first-order (Sampson) distance [px] of points (M,2) to the conic (3,3)."""
    p = np.column_stack([points, np.ones(len(points))])
    Cp = p @ conic
    f = np.einsum("ij,ij->i", Cp, p)
    grad = 2.0 * Cp[:, :2]
    return float(np.sqrt(np.mean(f**2 / np.einsum("ij,ij->i", grad, grad))))


def fit_ellipse(points: np.ndarray, method: str = "direct") -> np.ndarray:
    """OpenCV ellipse fit of (M,2) points -> (5,) ellipse. OpenCV fits in float32, so the
    points are centred and scaled to unit RMS radius first and the result mapped back.
    ValueError on fewer than 5 points, NaN/inf, or an unknown method."""
    if method not in FITTERS:
        raise ValueError(f"fit_ellipse: method must be one of {sorted(FITTERS)}, got {method!r}")
    points = check_points(points, "fit_ellipse: points", min_rows=5)
    mean = points.mean(axis=0)
    scale = np.sqrt(np.mean(np.sum((points - mean) ** 2, axis=1)))
    if not scale > 0:
        raise ValueError("rim points are all identical")
    with opencv_errors(f"fit_ellipse ({method}) of {len(points)} points"):
        (u0, v0), (w, h), ang = FITTERS[method](((points - mean) / scale).astype(np.float32))
    return np.array([u0 * scale + mean[0], v0 * scale + mean[1], w * scale, h * scale, ang])


def ellipse_points(ellipse: np.ndarray, n: int = 90) -> np.ndarray:
    """(n,2) points equally spaced in angle on an ellipse (5,) (OpenCV RotatedRect convention)."""
    u0, v0, w, h, ang = np.asarray(ellipse, dtype=float).reshape(5)
    phi = np.linspace(0.0, 2.0 * np.pi, int(n), endpoint=False)
    c, s = np.cos(np.radians(ang)), np.sin(np.radians(ang))
    x, y = 0.5 * w * np.cos(phi), 0.5 * h * np.sin(phi)
    return np.column_stack([u0 + c * x - s * y, v0 + s * x + c * y])


@dataclass(frozen=True)
class EllipseRefinement:
    """Result of `refine_ellipse`: ellipse (5,) (OpenCV RotatedRect convention, pixel
    coordinates of the coverage map's image), blur [px] (Gaussian sigma of the edge, optics
    and sensor), level_in / level_out (fitted coverage inside / outside), rms residual of the
    coverage, n_pixels in the edge band, and the 1-sigma [px] of the centre (2,) and of the
    two semi-axes (2,) from the fit's Gauss-Newton covariance."""

    ellipse: np.ndarray
    blur: float
    level_in: float
    level_out: float
    rms: float
    n_pixels: int
    centre_sigma: np.ndarray
    semi_axis_sigma: np.ndarray


def _ellipse_distance(u0, v0, a, b, angle, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """First-order (Sampson) signed distance [px] of pixels (u, v) to the ellipse with centre
    (u0, v0), semi-axes a, b and angle [rad]; negative inside."""
    c, s = np.cos(angle), np.sin(angle)
    x, y = u - u0, v - v0
    xr, yr = c * x + s * y, -s * x + c * y
    q = (xr / a) ** 2 + (yr / b) ** 2
    return (q - 1.0) / (2.0 * np.sqrt((xr / a**2) ** 2 + (yr / b**2) ** 2) + 1e-12)


def _edge_model(p: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Coverage of pixels (u, v) by a blurred filled ellipse p = (u0, v0, log a, log b, angle,
    log sigma, level_in, level_out): level_out + (level_in - level_out) Phi(-(d + sigma^2 k/2)
    / s), d the first-order (Sampson) signed distance to the ellipse, s^2 = sigma^2 + 1/12 (the
    pixel's box), k = 1/sqrt(ab) the mean curvature (a blurred convex edge's half level lies
    sigma^2 k / 2 inside it)."""
    u0, v0, la, lb, th, ls, lin, lout = p
    a, b, sigma = np.exp(la), np.exp(lb), np.exp(ls)
    d = _ellipse_distance(u0, v0, a, b, th, u, v) + 0.5 * sigma**2 / np.sqrt(a * b)
    return lout + (lin - lout) * 0.5 * erfc(d / np.sqrt(2.0 * (sigma**2 + 1.0 / 12.0)))


def refine_ellipse(
    coverage: np.ndarray,
    origin: tuple[int, int],
    ellipse0: np.ndarray,
    band: float = 4.0,
    blur0: float = 0.7,
    min_contrast: float = 0.5,
) -> EllipseRefinement:
    """Sub-pixel ellipse from a coverage map (seed 003 II-A-1 refined: the edge itself is the
    measurement): every pixel of `coverage` (the fraction covered by the disk; its pixel (0,0) at
    image pixel `origin`) within `band` px of ellipse0 (5,) fitted with `_edge_model` by
    Levenberg-Marquardt, in raw pixels. ValueError when the band is too small, the fit diverges or
    finds no edge (inside minus outside coverage <= min_contrast)."""
    coverage = np.asarray(coverage, dtype=float)
    u0, v0, w, h, ang = np.asarray(ellipse0, dtype=float).reshape(5)
    origin = np.asarray(origin, dtype=float).reshape(-1)
    if (
        origin.shape != (2,)
        or not np.isfinite(origin).all()
        or not (np.isfinite(band) and band > 0)
    ):
        raise ValueError(
            f"refine_ellipse: origin must be 2 finite numbers and band > 0, got {origin}, {band}"
        )
    if coverage.ndim != 2 or not (np.isfinite([u0, v0, w, h, ang]).all() and min(w, h) > 0):
        raise ValueError(
            f"refine_ellipse: need a 2-D coverage map and a finite start ellipse, got "
            f"{coverage.shape}, {ellipse0}"
        )
    v, u = np.mgrid[0 : coverage.shape[0], 0 : coverage.shape[1]]
    u, v = (u + origin[0]).ravel(), (v + origin[1]).ravel()
    values = coverage.ravel()
    p0 = np.array([u0, v0, np.log(w / 2), np.log(h / 2), np.radians(ang), np.log(blur0), 1.0, 0.0])
    near = (np.abs(_ellipse_distance(u0, v0, w / 2, h / 2, p0[4], u, v)) <= band) & np.isfinite(
        values
    )
    if near.sum() < 20:
        raise ValueError(
            f"refine_ellipse: only {int(near.sum())} pixels within {band} px of the start ellipse"
        )
    u, v, values = u[near], v[near], values[near]
    fit = least_squares(lambda p: _edge_model(p, u, v) - values, p0, method="lm")
    p = fit.x
    a, b = np.exp(p[2]), np.exp(p[3])
    if not (
        fit.success
        and np.isfinite(p).all()
        and 0.5 < a / (w / 2) < 2.0
        and 0.5 < b / (h / 2) < 2.0
        and np.hypot(p[0] - u0, p[1] - v0) < band
    ):
        raise ValueError(
            f"refine_ellipse: the edge fit diverged (start {np.round(ellipse0, 3)}, "
            f"end {np.round(p, 3)}, status {fit.status})"
        )
    if not p[6] - p[7] > min_contrast:
        raise ValueError(
            f"refine_ellipse: no edge -- fitted coverage inside {p[6]:.3f} vs outside {p[7]:.3f} "
            f"(need a difference > {min_contrast})"
        )
    dof = max(len(values) - len(p), 1)
    rms = float(np.sqrt(2.0 * fit.cost / dof))
    J = fit.jac
    try:
        cov = np.linalg.inv(J.T @ J) * rms**2
    except np.linalg.LinAlgError as exc:
        raise ValueError(f"refine_ellipse: singular edge fit ({exc})") from None
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    ellipse = np.array([p[0], p[1], 2 * a, 2 * b, np.degrees(p[4]) % 180.0])
    return EllipseRefinement(
        ellipse,
        float(np.exp(p[5])),
        float(p[6]),
        float(p[7]),
        rms,
        int(len(values)),
        sd[:2],
        np.array([a * sd[2], b * sd[3]]),
    )
