"""Camera models, pixel <-> unit bearing batched over rows: `PinholeCamera` (OpenCV pinhole +
Brown-Conrady, seed 001 Sec. IV-A, seed 000 Sec. VI) and `ParaboloidOmniCamera` (seed 000
Sec. II's panoramic cameras in the unified central-catadioptric model; docs/design_core.md,
"Cameras"). Rows that cannot be mapped give NaN and a False mask; a wrong shape is a ValueError."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np

_DIST_LENGTHS = (0, 4, 5, 8, 12, 14)  # what cv2.projectPoints / undistortPoints accept
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)


def check_rows(array, ncols: int, name: str) -> np.ndarray:
    """`array` as a float64 (M, ncols) array, or ValueError naming `name` and the shape."""
    try:
        out = np.asarray(array, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric (M,{ncols}) array: {exc}") from None
    if out.ndim != 2 or out.shape[1] != ncols:
        raise ValueError(f"{name} must have shape (M,{ncols}), got {out.shape}")
    return out


def normalize_rows(vectors: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length; zero or non-finite rows become NaN."""
    norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = vectors / norm
    out[~(np.isfinite(norm[..., 0]) & (norm[..., 0] > 0))] = np.nan
    return out


def _positive(value, name: str) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value}")
    return value


def _inside_image(pixels: np.ndarray, width: int, height: int) -> np.ndarray:
    """Pixel centres at integer coordinates; the image covers [-0.5, W-0.5] x [-0.5, H-0.5]."""
    u, v = pixels[:, 0], pixels[:, 1]
    with np.errstate(invalid="ignore"):
        return (u >= -0.5) & (u <= width - 0.5) & (v >= -0.5) & (v <= height - 0.5)


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole camera with OpenCV distortion `dist` = (k1, k2, p1, p2[, k3[, k4, k5, k6 ...]]).

    Camera frame: x right, y down, z forward (OpenCV). Pixels (u, v) with (0, 0) the centre
    of the top-left pixel.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    dist: tuple[float, ...] = ()

    def __post_init__(self):
        for name in ("fx", "fy"):
            object.__setattr__(self, name, _positive(getattr(self, name), f"PinholeCamera.{name}"))
        for name in ("cx", "cy"):
            value = float(getattr(self, name))
            if not math.isfinite(value):
                raise ValueError(f"PinholeCamera.{name} must be finite, got {value}")
            object.__setattr__(self, name, value)
        for name in ("width", "height"):
            value = getattr(self, name)
            if int(value) != value or int(value) <= 0:
                raise ValueError(f"PinholeCamera.{name} must be a positive integer, got {value}")
            object.__setattr__(self, name, int(value))
        dist = tuple(float(k) for k in self.dist)
        if len(dist) not in _DIST_LENGTHS:
            raise ValueError(
                f"PinholeCamera.dist must have one of {_DIST_LENGTHS} coefficients, got {len(dist)}"
            )
        if not all(math.isfinite(k) for k in dist):
            raise ValueError(f"PinholeCamera.dist must be finite, got {dist}")
        object.__setattr__(self, "dist", dist)

    def params(self) -> dict:
        """The intrinsics as a log's camera `params` (docs/log_format.md)."""
        out = {
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "width": self.width,
            "height": self.height,
        }
        return {**out, "dist": list(self.dist)} if self.dist else out

    @classmethod
    def from_fov(cls, width: int, height: int, fov: float, dist: tuple = ()) -> "PinholeCamera":
        """Square pixels, principal point at the image centre, horizontal `fov` [rad]. Seed 000:
        (640, 480, 2*pi/3); seed 001: (752, 480, pi/2)."""
        fov = _positive(fov, "fov")
        if fov >= math.pi:
            raise ValueError(f"fov must be < pi for a pinhole camera, got {fov}")
        f = 0.5 * width / math.tan(0.5 * fov)
        return cls(f, f, (width - 1) / 2.0, (height - 1) / 2.0, width, height, dist)

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def _dist_array(self) -> np.ndarray:
        return np.asarray(self.dist, dtype=float)

    def _radial(self, r: np.ndarray) -> np.ndarray:
        """The distorted normalized radius of undistorted radius r (tangential terms ignored):
        r (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)."""
        k = np.zeros(8)
        k[: len(self.dist)] = self.dist
        r2 = r * r
        with np.errstate(divide="ignore", invalid="ignore"):
            return (
                r
                * (1 + r2 * (k[0] + r2 * (k[1] + r2 * k[4])))
                / (1 + r2 * (k[5] + r2 * (k[6] + r2 * k[7])))
            )

    @cached_property
    def max_radius(self) -> float:
        """Largest undistorted normalized radius up to which `_radial` is increasing (inf
        without distortion), searched up to 3x the image-corner radius: beyond it the model
        folds back and cv2.projectPoints would put points outside the lens's view inside the
        image, so they count as not visible."""
        if not any(k for i, k in enumerate(self.dist) if i not in (2, 3)):
            return math.inf
        corner = max(
            math.hypot(u, v)
            for u in ((0 - self.cx) / self.fx, (self.width - 1 - self.cx) / self.fx)
            for v in ((0 - self.cy) / self.fy, (self.height - 1 - self.cy) / self.fy)
        )
        r = np.linspace(0.0, 3.0 * corner, 30001)
        increasing = np.diff(self._radial(r)) > 0
        return math.inf if increasing.all() else float(r[np.argmin(increasing)])

    @cached_property
    def max_distorted_radius(self) -> float:
        """Distorted normalized radius reached at max_radius (pixels beyond have no preimage)."""
        r = self.max_radius
        return float(self._radial(np.float64(r))) if math.isfinite(r) else math.inf

    def pixel_to_bearing(self, pixels) -> tuple[np.ndarray, np.ndarray]:
        """Observed (distorted) pixels (M,2) -> unit bearings (M,3) via cv2.undistortPoints;
        valid = finite input within the monotonic part of the distortion (max_distorted_radius)."""
        pixels = check_rows(pixels, 2, "pixels")
        with np.errstate(invalid="ignore"):
            distorted_r = np.hypot(
                (pixels[:, 0] - self.cx) / self.fx, (pixels[:, 1] - self.cy) / self.fy
            )
            valid = np.isfinite(pixels).all(axis=1) & (distorted_r <= self.max_distorted_radius)
        bearings = np.full((len(pixels), 3), np.nan)
        if valid.any():
            if self.dist:
                xy = cv2.undistortPoints(
                    pixels[valid].reshape(-1, 1, 2),
                    self.K,
                    self._dist_array(),
                    criteria=_UNDISTORT_CRITERIA,
                ).reshape(-1, 2)
            else:  # closed form; identical to undistortPoints without distortion
                xy = (pixels[valid] - (self.cx, self.cy)) / (self.fx, self.fy)
            bearings[valid] = normalize_rows(np.column_stack([xy, np.ones(len(xy))]))
        return bearings, valid

    def bearing_to_pixel(self, bearings) -> tuple[np.ndarray, np.ndarray]:
        """Bearings (M,3) (any positive length) -> pixels (M,2) via cv2.projectPoints.
        Rows with z <= 0, NaN, or beyond max_radius (distortion folds back) give NaN;
        visible = the others that land inside the image."""
        bearings = check_rows(bearings, 3, "bearings")
        with np.errstate(invalid="ignore", divide="ignore"):
            front = np.isfinite(bearings).all(axis=1) & (bearings[:, 2] > 0)
            front &= np.hypot(bearings[:, 0], bearings[:, 1]) < self.max_radius * bearings[:, 2]
        pixels = np.full((len(bearings), 2), np.nan)
        if front.any():
            if self.dist:
                pixels[front] = cv2.projectPoints(
                    bearings[front].reshape(-1, 1, 3),
                    np.zeros(3),
                    np.zeros(3),
                    self.K,
                    self._dist_array(),
                )[0].reshape(-1, 2)
            else:
                xy = bearings[front, :2] / bearings[front, 2:3]
                pixels[front] = xy * (self.fx, self.fy) + (self.cx, self.cy)
        return pixels, front & _inside_image(pixels, self.width, self.height)

    def project(self, points_cam) -> tuple[np.ndarray, np.ndarray]:
        """3D points in the camera frame (M,3) -> pixels (M,2), visible (M,)."""
        return self.bearing_to_pixel(check_rows(points_cam, 3, "points_cam"))


@dataclass(frozen=True)
class ParaboloidOmniCamera:
    """Panoramic camera of seed 000 section II (see the module docstring for the model).

    focal: effective focal length f_i [px] (= h * m, the image radius of the horizon).
    size: equivalent sensor resolution n_i (the image is size x size; seed 000 uses 512).
    conic_constant: k_i of the mirror; -1 for the paraboloid (xi = 1).
    cx, cy: image centre [px]; default (size - 1) / 2.
    max_polar_angle: field-of-view limit [rad] measured from the +z mirror axis (the image
      centre); > pi/2 sees below the horizon. min_polar_angle: the central blind spot
      (the camera's own reflection).
    Camera frame: z along the mirror axis toward the image centre (for a ground robot: up),
    x and y along the image u and v axes.
    """

    focal: float
    size: int
    conic_constant: float = -1.0
    cx: float | None = None
    cy: float | None = None
    max_polar_angle: float = 2.0 * math.pi / 3.0
    min_polar_angle: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "focal", _positive(self.focal, "ParaboloidOmniCamera.focal"))
        if int(self.size) != self.size or int(self.size) <= 0:
            raise ValueError(
                f"ParaboloidOmniCamera.size must be a positive integer, got {self.size}"
            )
        object.__setattr__(self, "size", int(self.size))
        k = float(self.conic_constant)
        if not (math.isfinite(k) and k <= -1.0):
            raise ValueError(
                f"ParaboloidOmniCamera.conic_constant must be <= -1 (paraboloid -1, "
                f"hyperboloid < -1), got {k}"
            )
        object.__setattr__(self, "conic_constant", k)
        for name in ("cx", "cy"):
            value = (
                (self.size - 1) / 2.0 if getattr(self, name) is None else float(getattr(self, name))
            )
            if not math.isfinite(value):
                raise ValueError(f"ParaboloidOmniCamera.{name} must be finite, got {value}")
            object.__setattr__(self, name, value)
        lo, hi = float(self.min_polar_angle), float(self.max_polar_angle)
        # directions with d_z <= -xi have no image; keep the FOV strictly inside
        limit = math.pi - math.acos(min(self.xi, 1.0)) if self.xi < 1.0 else math.pi
        if not (0.0 <= lo < hi < limit):
            raise ValueError(
                f"ParaboloidOmniCamera needs 0 <= min_polar_angle < max_polar_angle < {limit:.6f}, "
                f"got {lo}, {hi}"
            )
        object.__setattr__(self, "min_polar_angle", lo)
        object.__setattr__(self, "max_polar_angle", hi)

    @classmethod
    def from_fov(
        cls,
        size: int,
        max_polar_angle: float = 2.0 * math.pi / 3.0,
        conic_constant: float = -1.0,
        min_polar_angle: float = 0.0,
    ) -> "ParaboloidOmniCamera":
        """Focal length such that the FOV limit `max_polar_angle` touches the edge of the
        size x size image (radius size/2)."""
        if not conic_constant <= -1.0:
            raise ValueError(f"conic_constant must be <= -1, got {conic_constant}")
        theta = float(max_polar_angle)
        focal = 0.5 * size * (math.cos(theta) + _xi(conic_constant)) / math.sin(theta)
        return cls(focal, size, conic_constant, None, None, theta, min_polar_angle)

    @property
    def xi(self) -> float:
        return _xi(self.conic_constant)

    def _in_fov(self, bearings: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            cos_polar = np.clip(bearings[:, 2], -1.0, 1.0)
            return (cos_polar <= math.cos(self.min_polar_angle)) & (
                cos_polar >= math.cos(self.max_polar_angle)
            )

    def pixel_to_bearing(self, pixels) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (M,2) -> unit bearings (M,3) (closed-form lifting); valid = finite input (the
        lifting is defined for every pixel, as the pinhole's is within its distortion model).
        The FOV limits [min_polar_angle, max_polar_angle] are a property of projection
        (`bearing_to_pixel`'s `visible`): a measured pixel that noise pushed just past the mirror
        rim still lifts to the bearing it measures."""
        pixels = check_rows(pixels, 2, "pixels")
        xi = self.xi
        xy = (pixels - (self.cx, self.cy)) / self.focal
        r2 = np.einsum("ij,ij->i", xy, xy)
        s = (xi + np.sqrt(1.0 + (1.0 - xi * xi) * r2)) / (r2 + 1.0)
        bearings = np.column_stack([s * xy[:, 0], s * xy[:, 1], s - xi])
        finite = np.isfinite(bearings).all(axis=1)
        bearings[~finite] = np.nan
        return bearings, finite

    def bearing_to_pixel(self, bearings) -> tuple[np.ndarray, np.ndarray]:
        """Bearings (M,3) (any positive length) -> pixels (M,2); NaN where d_z <= -xi
        (no image); visible = within the FOV and inside the image."""
        d = normalize_rows(check_rows(bearings, 3, "bearings"))
        with np.errstate(invalid="ignore", divide="ignore"):
            denom = d[:, 2] + self.xi
            imaged = np.isfinite(denom) & (denom > 1e-12)
            pixels = np.full((len(d), 2), np.nan)
            pixels[imaged] = self.focal * d[imaged, :2] / denom[imaged, None] + (self.cx, self.cy)
        visible = imaged & self._in_fov(d) & _inside_image(pixels, self.size, self.size)
        return pixels, visible

    def project(self, points_cam) -> tuple[np.ndarray, np.ndarray]:
        """3D points in the camera frame (M,3) (origin = the mirror focus) -> pixels, visible."""
        return self.bearing_to_pixel(check_rows(points_cam, 3, "points_cam"))


def _xi(conic_constant: float) -> float:
    """Unified-model mirror parameter, 2e/(1+e^2) with e = sqrt(-k); 1 for the paraboloid."""
    e = math.sqrt(-conic_constant)
    return 2.0 * e / (1.0 + e * e)


def angular_sigma(
    camera, pixels: np.ndarray, pixel_sigma: float, floor: float = 1e-5
) -> np.ndarray:
    """Per-axis bearing sigma [rad] (...,) of pixels (...,2) with seed 000's pixel noise (Sec.
    VI-A: N(0, sigma) px along a random direction, per-axis std sigma / sqrt 2), times the
    camera's local angle per pixel (finite differences of pixel_to_bearing: works for the
    pinhole and the omni)."""
    flat = np.asarray(pixels, dtype=float).reshape(-1, 2)
    b0, _ = camera.pixel_to_bearing(flat)
    bu, _ = camera.pixel_to_bearing(flat + (1.0, 0.0))
    bv, _ = camera.pixel_to_bearing(flat + (0.0, 1.0))
    per_px = 0.5 * (
        np.arccos(np.clip(np.sum(b0 * bu, axis=1), -1, 1))
        + np.arccos(np.clip(np.sum(b0 * bv, axis=1), -1, 1))
    )
    return np.maximum(pixel_sigma / np.sqrt(2.0) * per_px, floor).reshape(np.shape(pixels)[:-1])
