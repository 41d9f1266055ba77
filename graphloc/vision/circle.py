"""Pose of a circle of known radius from its image ellipse (seed 003, section II-A "Robot
Tracker": 1) ellipse detection and least-squares fit to edge points, 2) position from the
ellipse via the oblique elliptical cone, eqs. (1)-(4)).

Pipeline (batched over N rims where it matters):
  rim pixels (M,2) -> undistorted ideal pixels (camera model) -> OpenCV ellipse fit
  (cv2.fitEllipseDirect, Fitzgibbon's direct least squares, the seed's "least-squares
  fitting technique [3]"; AMS / plain fitEllipse selectable) -> image conic C (3x3)
  -> cone Q = K^T C K through the camera centre (seed eq. 1, in normalized coordinates)
  -> eigen-decomposition Q = V diag(l1, l2, l3) V^T, l1 >= l2 > 0 > l3 (the seed's
  "rotation R1 by diagonalizing") -> the two circular sections (seed eqs. 2-3; Shiu & Ahmad
  1989, Safaee-Rad et al. 1992):

    Q - l2 I = (l1 - l3) (n . P)(m . P),  n, m = (+-sqrt(l1-l2), 0, +-sqrt(l2-l3)) / sqrt(l1-l3)

  so on a plane n . P = d the cone is the sphere |P|^2 + (l1-l3) d (m . P) / l2 = 0, whose
  section by that plane is the circle; its radius fixes d, its centre is the projection of
  the sphere centre onto the plane (closed form, the seed's eq. 4).

Both solutions (normal sign choices +-sqrt(l1-l2)) are returned, as a CandidateSet of
circle-frame poses T_cam_circle: origin = circle centre, z axis = the circle's normal turned
towards the camera (n . centre < 0). Rotation about the normal (yaw) is unobservable for a
circle; convention: the circle's x axis is the camera x axis projected onto the circle plane
(camera y axis if x is within 1e-6 of the normal). Both candidates share one score,
exp(-rms^2 / (2 sigma^2)) of the RMS Sampson distance [px] of the rim points to the fitted
ellipse -- the ellipse cannot tell the two apart; engines choose.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.special import erfc

from graphloc.config import check
from graphloc.cameras import PinholeCamera, check_rows, normalize_rows
from graphloc.candidates import CandidateSet
from graphloc.vision.images import check_points, opencv_errors

_FITTERS = {"direct": cv2.fitEllipseDirect, "ams": cv2.fitEllipseAMS, "lsq": cv2.fitEllipse}
STATUS_OK = "ok"
STATUS_TOO_FEW = "too_few_points"  # fewer than min_points finite rim points
STATUS_EDGE_ON = "edge_on"  # collinear rim or ellipse axis ratio < min_axis_ratio
STATUS_FIT_FAILED = "fit_failed"  # OpenCV returned a non-finite or empty ellipse
STATUS_NO_CONE = "no_real_cone"  # the ellipse does not back-project to a real elliptic cone


@dataclass(frozen=True)
class CircleConfig:
    """min_points: rim points needed after dropping non-finite ones (OpenCV needs >= 5).
    min_axis_ratio: minor/major axis of the fitted ellipse below which the circle counts as
    seen edge-on (no usable normal). pixel_sigma: rim noise [px] used in the score.
    fit: 'direct' (cv2.fitEllipseDirect), 'ams' (cv2.fitEllipseAMS) or 'lsq' (cv2.fitEllipse)."""

    min_points: int = 6
    min_axis_ratio: float = 0.05
    pixel_sigma: float = 1.0
    fit: str = "direct"

    def __post_init__(self):
        check(
            self,
            choices={"fit": tuple(sorted(_FITTERS))},
            integer={"min_points": 5},
            interval={"min_axis_ratio": (0.0, 1.0, "()")},
            positive=("pixel_sigma",),
        )


@dataclass(frozen=True)
class CirclePoses:
    """Result for N rims. centres, normals: (N,2,3) in the camera frame, NaN where status[n]
    is not 'ok'; ellipses: (N,5) fitted ellipse in ideal (undistorted) pixels as
    (u0, v0, full width, full height, angle deg) in OpenCV's RotatedRect convention;
    rms_px (N,): RMS Sampson distance of the rim to the ellipse; n_points (N,) used,
    n_skipped (N,) non-finite rim rows dropped; status (N,): one of the STATUS_* codes
    ('ok', 'too_few_points', 'edge_on', 'fit_failed', 'no_real_cone'); explain(n) gives the
    numbers behind it."""

    centres: np.ndarray
    normals: np.ndarray
    ellipses: np.ndarray
    rms_px: np.ndarray
    n_points: np.ndarray
    n_skipped: np.ndarray
    status: np.ndarray
    radius: float
    pixel_sigma: float

    def __len__(self) -> int:
        return len(self.status)

    @property
    def ok(self) -> np.ndarray:
        return self.status == STATUS_OK

    def explain(self, n: int) -> str:
        """One line: rim n's status with the numbers behind it."""
        w, h = self.ellipses[n, 2], self.ellipses[n, 3]
        ratio = (
            min(w, h) / max(w, h) if np.isfinite([w, h]).all() and max(w, h) > 0 else float("nan")
        )
        return (
            f"circle rim {n}: {self.status[n]} ({self.n_points[n]} finite rim points, "
            f"{self.n_skipped[n]} non-finite skipped, ellipse axis ratio {ratio:.3g})"
        )

    def candidates(
        self, n: int = 0, time: float = 0.0, observer: str = "", observed: str = ""
    ) -> CandidateSet:
        """The two poses T_cam_circle of rim n (ValueError if rim n failed)."""
        if self.status[n] != STATUS_OK:
            raise ValueError(self.explain(n))
        R = rotations_from_normals(self.normals[n])
        score = np.exp(-0.5 * (self.rms_px[n] / self.pixel_sigma) ** 2)
        return CandidateSet(
            R,
            self.centres[n],
            np.full(2, score),
            time,
            observer,
            observed,
            "circle",
            meta={
                "rms_px": float(self.rms_px[n]),
                "n_points": int(self.n_points[n]),
                "n_skipped": int(self.n_skipped[n]),
                "radius": self.radius,
            },
        )


def rotations_from_normals(normals: np.ndarray) -> np.ndarray:
    """(K,3) unit normals -> (K,3,3) rotations with z = normal, x = camera x projected on the
    plane (camera y when x is parallel to the normal); see the module docstring."""
    normals = normalize_rows(check_rows(normals, 3, "normals"))
    ref = np.tile([1.0, 0.0, 0.0], (len(normals), 1))
    ref[np.abs(normals[:, 0]) > 1.0 - 1e-6] = (0.0, 1.0, 0.0)
    x = normalize_rows(ref - np.einsum("ij,ij->i", ref, normals)[:, None] * normals)
    y = np.cross(normals, x)
    return np.stack([x, y, normals], axis=2)


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
    if method not in _FITTERS:
        raise ValueError(f"fit_ellipse: method must be one of {sorted(_FITTERS)}, got {method!r}")
    points = check_points(points, "fit_ellipse: points", min_rows=5)
    mean = points.mean(axis=0)
    scale = np.sqrt(np.mean(np.sum((points - mean) ** 2, axis=1)))
    if not scale > 0:
        raise ValueError("rim points are all identical")
    with opencv_errors(f"fit_ellipse ({method}) of {len(points)} points"):
        (u0, v0), (w, h), ang = _FITTERS[method](((points - mean) / scale).astype(np.float32))
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
    """Sub-pixel ellipse from a coverage map (seed 003 II-A-1 refined: the seed fits edge
    points; here the edge itself is the measurement). coverage (h,w): the fraction of each
    pixel covered by the disk (e.g. `vision.base_rim.coverage_map`), its pixel (0,0) at image
    pixel `origin` (x0, y0); ellipse0 (5,): the starting ellipse (cv2 fit of edge points).
    Fits every pixel within `band` px of ellipse0 with `_edge_model` by Levenberg-Marquardt
    (scipy.optimize.least_squares). Edge points interpolated between pixel centres lock onto
    the pixel grid (their ellipse size wobbles as the image moves); the edge model does not.
    The fit is in raw pixels: under lens distortion the rim is an ellipse only to first order
    across the blob (points on it are undistorted afterwards by `circle_poses_from_rims`).
    ValueError when the band is too small, the fit diverges or finds no edge (fitted inside
    minus outside coverage <= min_contrast)."""
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


def circles_from_cones(
    cones: np.ndarray, radius: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed-form circle centres and normals from (N,3,3) cones P^T Q P = 0 (camera frame,
    normalized coordinates). Returns centres (N,2,3), normals (N,2,3) (towards the camera,
    centre z > 0) and ok (N,) -- False where Q is not a real elliptic cone (signature != (2,1))."""
    Q = np.asarray(cones, dtype=float)
    lam, V = np.linalg.eigh(Q)  # ascending
    n_pos = (lam > 0).sum(axis=1)
    flip = n_pos == 1  # make two eigenvalues positive, one negative
    lam = np.where(flip[:, None], -lam[:, ::-1], lam)
    V = np.where(flip[:, None, None], V[:, :, ::-1], V)
    ok = np.isin(n_pos, (1, 2)) & np.isfinite(lam).all(axis=1)
    l3, l2, l1 = lam[:, 0], lam[:, 1], lam[:, 2]
    ok &= (l3 < 0) & (l2 > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        span = l1 - l3
        s = np.sqrt(np.maximum(l1 - l2, 0.0) / span)
        t = np.sqrt(np.maximum(l2 - l3, 0.0) / span)
        kappa = span / (2.0 * l2)
        centres, normals = [], []
        for sign in (1.0, -1.0):
            # eigen frame (axes ordered l1, l2, l3): n = (sign s, 0, t), m = (sign s, 0, -t)
            n_e = np.stack([sign * s, np.zeros_like(s), t], -1)
            m_e = np.stack([sign * s, np.zeros_like(s), -t], -1)
            nm = sign * sign * s * s - t * t
            d = radius / np.sqrt(kappa**2 - (1.0 + kappa * nm) ** 2)
            c_e = -kappa[:, None] * d[:, None] * m_e + (d * (1.0 + kappa * nm))[:, None] * n_e
            frame = V[:, :, ::-1]  # columns: eigenvectors of l1, l2, l3
            c = np.einsum("nij,nj->ni", frame, c_e)
            n = np.einsum("nij,nj->ni", frame, n_e)
            c *= np.where(c[:, 2] < 0, -1.0, 1.0)[:, None]  # d -> -d mirrors the solution
            n *= np.where(np.einsum("ni,ni->n", n, c) > 0, -1.0, 1.0)[:, None]
            centres.append(c)
            normals.append(n)
    centres, normals = np.stack(centres, 1), np.stack(normals, 1)
    ok &= np.isfinite(centres).all(axis=(1, 2)) & np.isfinite(normals).all(axis=(1, 2))
    centres[~ok] = np.nan
    normals[~ok] = np.nan
    return centres, normals, ok


def circle_poses_from_rims(
    camera: PinholeCamera,
    rims: Sequence[np.ndarray] | np.ndarray,
    radius: float,
    config: CircleConfig = CircleConfig(),
) -> CirclePoses:
    """Circle poses from N rims: rims is a sequence of (M_i,2) raw pixel arrays or an
    (N,M,2) array. Per-rim problems (too few finite points, edge-on, no real cone) are
    reported as `status` codes, never raised; wrong shapes and a bad radius are ValueErrors."""
    radius = float(radius)
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive finite number, got {radius}")
    if not isinstance(camera, PinholeCamera):
        raise ValueError(
            f"camera must be a PinholeCamera (the cone needs a perspective K), "
            f"got {type(camera).__name__}"
        )
    if isinstance(rims, np.ndarray) and rims.ndim == 3:
        rims = list(rims)
    rims = [check_rows(r, 2, f"rims[{i}]") for i, r in enumerate(rims)]
    N = len(rims)
    ellipses = np.full((N, 5), np.nan)
    rms = np.full(N, np.nan)
    status = np.full(N, STATUS_OK, dtype=object)
    # all rims undistorted in one call: ideal pixels K [x/z, y/z, 1]
    lengths = np.array([len(r) for r in rims], dtype=int)
    bearings, valid = camera.pixel_to_bearing(np.concatenate(rims) if N else np.zeros((0, 2)))
    ideal_all = bearings[:, :2] / bearings[:, 2:3] * (camera.fx, camera.fy) + (camera.cx, camera.cy)
    splits = np.cumsum(lengths)[:-1]
    valid_per_rim = np.split(valid, splits)[:N]  # [:N]: np.split of nothing still gives one piece
    ideal_rims = [ideal[v] for ideal, v in zip(np.split(ideal_all, splits), valid_per_rim)]
    n_points = np.array([v.sum() for v in valid_per_rim], dtype=int).reshape(N)
    n_skipped = lengths - n_points
    for i, ideal in enumerate(ideal_rims):
        if n_points[i] < config.min_points:
            status[i] = STATUS_TOO_FEW
            continue
        if (
            np.linalg.matrix_rank(ideal - ideal.mean(0), tol=1e-9 * max(1.0, np.abs(ideal).max()))
            < 2
        ):
            status[i] = STATUS_EDGE_ON
            continue
        ellipses[i] = fit_ellipse(ideal, config.fit)
        w, h = ellipses[i, 2], ellipses[i, 3]
        if not (np.isfinite(ellipses[i]).all() and min(w, h) > 0):
            status[i] = STATUS_FIT_FAILED
            continue
        if min(w, h) / max(w, h) < config.min_axis_ratio:
            status[i] = STATUS_EDGE_ON
    good = np.flatnonzero(status == STATUS_OK)
    conics = ellipse_to_conic(ellipses[good])
    for k, i in enumerate(good):
        rms[i] = sampson_rms(conics[k], ideal_rims[i])
    K = camera.K
    cones = np.einsum("ji,njk,kl->nil", K, conics, K)  # K^T C K
    centres = np.full((N, 2, 3), np.nan)
    normals = np.full((N, 2, 3), np.nan)
    c, n, ok = circles_from_cones(cones, radius)
    centres[good], normals[good] = c, n
    status[good[~ok]] = STATUS_NO_CONE
    return CirclePoses(
        centres,
        normals,
        ellipses,
        rms,
        n_points,
        n_skipped,
        status.astype(str),
        radius,
        config.pixel_sigma,
    )


def circle_pose_from_rim(
    camera: PinholeCamera,
    rim: np.ndarray,
    radius: float,
    config: CircleConfig = CircleConfig(),
    time: float = 0.0,
    observer: str = "",
    observed: str = "",
) -> tuple[CandidateSet, CirclePoses]:
    """One rim (M,2) of raw pixels -> (CandidateSet of the 2 poses, CirclePoses of length 1).
    ValueError (with the reason) when the rim is unusable."""
    poses = circle_poses_from_rims(camera, [check_rows(rim, 2, "rim")], radius, config)
    if not poses.ok[0]:
        raise ValueError(poses.explain(0))
    return poses.candidates(0, time, observer, observed), poses


def rim_points_from_mask(mask: np.ndarray) -> np.ndarray:
    """Boundary pixels (M,2) (u, v) of the largest blob of a binary mask (seed 003 II-A-1:
    colour threshold -> median filter -> edges), via cv2.findContours."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"mask must be a 2-D image, got shape {mask.shape}")
    if mask.dtype.kind not in "biuf":
        raise ValueError(f"mask must be a numeric or boolean image, got dtype {mask.dtype}")
    if mask.size == 0:
        raise ValueError(f"mask is empty (shape {mask.shape})")
    with opencv_errors(f"rim_points_from_mask on a {mask.shape[1]}x{mask.shape[0]} mask"):
        contours, _ = cv2.findContours(
            (mask > 0).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE
        )
    if not contours:
        raise ValueError("mask has no foreground blob")
    return max(contours, key=cv2.contourArea).reshape(-1, 2).astype(float)
