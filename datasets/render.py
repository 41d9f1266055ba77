"""Forward models of the simulators (never used by a front-end): seed 000's mutual omni pixels,
seed 003's base rim, and camera frames of spherical markers (seed 001 Sec. III, V-A), rendered
by sub-pixel bearing tests (docs/design_datasets.md, "Rendered markers")."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from graphloc.vision.circle import rotations_from_normals
from graphloc.vision.mutual import three_cameras


@config_dataclass
class RenderConfig:
    """Radiometry of a rendered frame: levels are grey values (0-255), or BGR triples with
    `color=True`; active markers are brighter than the background, painted ones darker."""

    background: float | tuple[float, float, float] = 60.0
    marker_level: float | tuple[float, float, float] = 220.0
    # background brightness change across the image width [grey levels]
    gradient: float = setting(20.0, ge=0.0)
    blur_sigma: float = setting(0.7, ge=0.0)  # optics [px]; 0 = none
    noise_sigma: float = setting(2.0, ge=0.0)  # sensor noise [grey levels]
    supersample: int = setting(4, ge=1)
    color: bool = False

    def __post_init__(self):
        c = 3 if self.color else 1
        for name in ("background", "marker_level"):
            level = np.atleast_1d(np.asarray(getattr(self, name), dtype=float))
            if level.shape != (c,) or not np.isfinite(level).all():
                raise ValueError(
                    f"RenderConfig.{name} must be {c} finite value(s) for color={self.color}, "
                    f"got {getattr(self, name)}"
                )

    def levels(self, value) -> np.ndarray:
        return np.atleast_1d(np.asarray(value, dtype=np.float32))


@dataclass(frozen=True)
class Occluder:
    """An axis-aligned rectangle (x0, y0, x1, y1) [px, pixel-edge coordinates] in front of all
    markers, with grey level or BGR `level`."""

    rect: tuple[float, float, float, float]
    level: float | tuple[float, float, float]


@dataclass(frozen=True)
class RenderedFrame:
    """image: (H,W) or (H,W,3) uint8. Per marker (M rows, NaN when not visible at all):
    centers (M,2) projected sphere centres, centroids (M,2) centroid of the visible area,
    radii (M,) angular-radius projected to pixels (fx * tan(asin(r/|c|))), visible (M,) visible
    fraction of the full marker image (0 = hidden / outside, 1 = fully visible)."""

    image: np.ndarray
    centers: np.ndarray
    centroids: np.ndarray
    radii: np.ndarray
    visible: np.ndarray


def image_size(camera) -> tuple[int, int]:
    """(width, height) of a camera model (PinholeCamera width/height, omni `size`)."""
    if hasattr(camera, "width"):
        return int(camera.width), int(camera.height)
    return int(camera.size), int(camera.size)


def _orthonormal_basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


def _marker_box(camera, axis, half_angle, width, height):
    """Pixel bounding box (x0, y0, x1, y1) of the cone's image (+2 px), or None if it does not
    project (e.g. crosses the pinhole plane)."""
    e1, e2 = _orthonormal_basis(axis)
    phi = np.linspace(0.0, 2.0 * np.pi, 48, endpoint=False)
    a = min(half_angle * 1.05 + 1e-4, np.pi / 2)
    rim = np.cos(a) * axis + np.sin(a) * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    px, _ = camera.bearing_to_pixel(np.vstack([rim, axis[None]]))
    if not np.isfinite(px).all():
        return None
    x0, y0 = np.floor(px.min(axis=0)).astype(int) - 2
    x1, y1 = np.ceil(px.max(axis=0)).astype(int) + 3
    if x1 <= 0 or y1 <= 0 or x0 >= width or y0 >= height:
        return None
    if (x1 - x0) * (y1 - y0) > 16 * width * height:
        return None
    return x0, y0, x1, y1


def _subpixel_grid(box, s):
    x0, y0, x1, y1 = box
    offs = (np.arange(s) + 0.5) / s - 0.5
    xs = (np.arange(x0, x1)[:, None] + offs[None]).ravel()
    ys = (np.arange(y0, y1)[:, None] + offs[None]).ravel()
    gx, gy = np.meshgrid(xs, ys)
    return gx, gy


def _in_rects(gx, gy, rects: np.ndarray) -> np.ndarray:
    if len(rects) == 0:
        return np.zeros(gx.shape, bool)
    r = rects[:, :, None, None]
    return ((gx >= r[:, 0]) & (gx < r[:, 2]) & (gy >= r[:, 1]) & (gy < r[:, 3])).any(axis=0)


def _rect_coverage(rect, width, height) -> np.ndarray:
    """Exact area fraction of every pixel covered by a rectangle (outer product of overlaps)."""
    x0, y0, x1, y1 = rect
    u = np.arange(width, dtype=np.float32)
    v = np.arange(height, dtype=np.float32)
    ox = np.clip(np.minimum(u + 0.5, x1) - np.maximum(u - 0.5, x0), 0.0, 1.0)
    oy = np.clip(np.minimum(v + 0.5, y1) - np.maximum(v - 0.5, y0), 0.0, 1.0)
    return np.outer(oy, ox)


def render_markers(
    camera,
    markers_cam: np.ndarray,
    marker_radius: float,
    config: RenderConfig = RenderConfig(),
    rng: np.random.Generator | None = None,
    backdrop: Callable[[np.ndarray], None] | None = None,
    occluders: tuple[Occluder, ...] = (),
    gains: np.ndarray | None = None,
) -> RenderedFrame:
    """Render spheres of radius `marker_radius` [m] centred at `markers_cam` (M,3) [m, camera
    frame]; `backdrop(image)` draws distractors into the float background first, in place;
    gains (M,): each marker's contrast in [0, 1] (a dim LED), default 1. ValueError for a wrong
    shape, NaN, or a sphere that contains the camera centre."""
    pts = np.asarray(markers_cam, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"render_markers: markers_cam must be (M,3), got {pts.shape}")
    if not np.isfinite(pts).all():
        raise ValueError("render_markers: markers_cam contains NaN/inf")
    if not (np.isfinite(marker_radius) and marker_radius > 0):
        raise ValueError(f"render_markers: marker_radius must be positive, got {marker_radius}")
    dist = np.linalg.norm(pts, axis=1)
    if (dist <= marker_radius).any():
        raise ValueError(
            "render_markers: camera inside marker(s) "
            f"{np.flatnonzero(dist <= marker_radius).tolist()}"
        )
    gains = np.ones(len(pts)) if gains is None else np.asarray(gains, dtype=float)
    if gains.shape != (len(pts),) or not (
        np.isfinite(gains).all() and (gains >= 0).all() and (gains <= 1).all()
    ):
        raise ValueError(
            f"render_markers: gains must be ({len(pts)},) values in [0, 1], got {gains}"
        )
    rng = np.random.default_rng() if rng is None else rng
    width, height = image_size(camera)
    s = config.supersample
    bg = config.levels(config.background)
    fg = config.levels(config.marker_level)
    nch = len(bg)

    # background with a horizontal gradient, then the backdrop (behind everything)
    ramp = (np.arange(width, dtype=np.float32) / max(width - 1, 1) - 0.5) * config.gradient
    img = np.empty((height, width, nch), np.float32)
    img[:] = bg[None, None, :] + ramp[None, :, None]
    if backdrop is not None:
        img = np.ascontiguousarray(img[..., 0]) if nch == 1 else img
        backdrop(img)
        img = img.reshape(height, width, nch)

    axes = pts / dist[:, None]
    half = np.arcsin(marker_radius / dist)
    cos_half = np.cos(half)
    order = np.argsort(dist)  # nearest first: they hide the farther ones
    rects = np.array([o.rect for o in occluders], dtype=float).reshape(-1, 4)
    M = len(pts)
    centers, _ = camera.project(pts)
    centroids = np.full((M, 2), np.nan)
    visible = np.zeros(M)
    radii = camera.fx * np.tan(half) if hasattr(camera, "fx") else np.full(M, np.nan)
    coverage = np.zeros((height, width), np.float32)
    for rank, i in enumerate(order):  # loop over markers (few), numpy over their pixels
        box = _marker_box(camera, axes[i], half[i], width, height)
        if box is None:
            continue
        gx, gy = _subpixel_grid(box, s)
        bear, ok = camera.pixel_to_bearing(np.column_stack([gx.ravel(), gy.ravel()]))
        bear = np.where(ok[:, None], bear, 0.0)
        hit = (bear @ axes[i] >= cos_half[i]).reshape(gx.shape)
        total = hit.sum()
        if total == 0:
            continue
        for j in order[:rank]:
            hit &= ~((bear @ axes[j] >= cos_half[j]).reshape(gx.shape))
        hit &= ~_in_rects(gx, gy, rects)
        hit &= (gx >= -0.5) & (gx < width - 0.5) & (gy >= -0.5) & (gy < height - 0.5)
        n_vis = hit.sum()
        visible[i] = n_vis / total
        if n_vis == 0:
            continue
        centroids[i] = gx[hit].mean(), gy[hit].mean()
        x0, y0, x1, y1 = box
        cov = hit.reshape(y1 - y0, s, x1 - x0, s).mean(axis=(1, 3))
        cx0, cy0 = max(x0, 0), max(y0, 0)
        cx1, cy1 = min(x1, width), min(y1, height)
        coverage[cy0:cy1, cx0:cx1] += gains[i] * cov[cy0 - y0 : cy1 - y0, cx0 - x0 : cx1 - x0]

    if occluders:
        occ = np.zeros((height, width), np.float32)
        occ_img = np.zeros((height, width, nch), np.float32)
        for o in occluders:  # later occluders on top ("over" compositing)
            c = _rect_coverage(o.rect, width, height)
            occ_img = (
                occ_img * (1.0 - c[..., None])
                + config.levels(o.level)[None, None, :] * c[..., None]
            )
            occ = occ + c * (1.0 - occ)
        coverage = np.minimum(coverage, 1.0 - occ)
        img = (
            img * np.clip(1.0 - coverage - occ, 0.0, 1.0)[..., None]
            + fg * coverage[..., None]
            + occ_img
        )
    else:
        img = img * (1.0 - coverage)[..., None] + fg * coverage[..., None]
    if config.blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), config.blur_sigma).reshape(height, width, nch)
    if config.noise_sigma > 0:
        img += config.noise_sigma * rng.standard_normal(img.shape, dtype=np.float32)
    out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    out = out[..., 0] if nch == 1 else out
    return RenderedFrame(
        image=out,
        centers=np.where(visible[:, None] > 0, centers, np.nan),
        centroids=centroids,
        radii=radii,
        visible=visible,
    )


def render_mutual_pixels(
    R_world: np.ndarray, t_world: np.ndarray, cameras
) -> tuple[np.ndarray, np.ndarray]:
    """Forward model: pixels (N,3,3,2) of each camera centre in the other cameras' images
    and visibility (N,3,3) (diagonal: NaN / False). R_world (N,3,3,3), t_world (N,3,3):
    camera-to-world rotations and camera centres of the 3 robots."""
    R_world, t_world = np.asarray(R_world, dtype=float), np.asarray(t_world, dtype=float)
    N = len(R_world)
    if R_world.shape != (N, 3, 3, 3) or t_world.shape != (N, 3, 3):
        raise ValueError(
            f"R_world must be (N,3,3,3) and t_world (N,3,3), got {R_world.shape}, {t_world.shape}"
        )
    cams = three_cameras(cameras)
    pixels = np.full((N, 3, 3, 2), np.nan)
    visible = np.zeros((N, 3, 3), dtype=bool)
    for i in range(3):
        others = [j for j in range(3) if j != i]
        # R_i^T (t_j - t_i)
        rel = np.einsum("nji,nkj->nki", R_world[:, i], t_world[:, others] - t_world[:, i, None])
        p, v = cams[i].project(rel.reshape(-1, 3))
        pixels[:, i, others] = p.reshape(N, 2, 2)
        visible[:, i, others] = v.reshape(N, 2)
    return pixels, visible


def render_circle_rim(
    camera, centre: np.ndarray, normal: np.ndarray, radius: float, n_points: int = 100
) -> tuple[np.ndarray, np.ndarray]:
    """Forward model: pixels (n_points,2) and visibility of n_points equally spaced points
    of the circle (camera frame centre (3,), normal (3,), radius)."""
    centre = np.asarray(centre, dtype=float).reshape(3)
    R = rotations_from_normals(np.asarray(normal, dtype=float).reshape(1, 3))[0]
    phi = np.linspace(0.0, 2.0 * np.pi, int(n_points), endpoint=False)
    points = centre + radius * (np.outer(np.cos(phi), R[:, 0]) + np.outer(np.sin(phi), R[:, 1]))
    return camera.project(points)
