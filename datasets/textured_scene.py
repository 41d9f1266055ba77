"""The rendering of scenario `crawler-pair` (seed 003 Sec. III): a textured wall and ground ray
cast per pixel, and the exact pixel coverage of the teammate's circular base."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.datasets.render import render_circle_rim


@dataclass(frozen=True)
class TexturedScene:
    """Back wall z = wall_z and ground y = ground_y, each with a BGR texture of `texel` m/px;
    wall texture covers x in [x0, x0 + W texel], y in [y0, ...]; ground x in [x0, ...],
    z in [z0, ...]."""

    wall_z: float
    ground_y: float
    texel: float
    wall_texture: np.ndarray
    wall_origin: tuple[float, float]
    ground_texture: np.ndarray
    ground_origin: tuple[float, float]

    def image(
        self, camera: PinholeCamera, supersample: int, R_wc: np.ndarray, t_wc: np.ndarray
    ) -> np.ndarray:
        """(H,W,3) float32 BGR of the textured wall and ground seen by `camera` at (R_wc, t_wc):
        supersample^2 rays per pixel hit the wall or the ground (ray-plane intersection), the
        texture is sampled with cv2.remap and cv2.resize(INTER_AREA) averages the rays."""
        cam, s = camera, int(supersample)
        W, H = cam.width * s, cam.height * s
        u = ((np.arange(W, dtype=np.float32) + 0.5) / s - 0.5 - cam.cx) / cam.fx
        v = ((np.arange(H, dtype=np.float32) + 0.5) / s - 0.5 - cam.cy) / cam.fy
        Rf = R_wc.astype(np.float32)
        # world ray components of pixel (v, u): R[:, 0] u + R[:, 1] v + R[:, 2], as (H,W) arrays
        ray = [Rf[i, 0] * u[None, :] + Rf[i, 1] * v[:, None] + Rf[i, 2] for i in range(3)]
        o = t_wc.astype(np.float32)
        with np.errstate(divide="ignore", invalid="ignore"):
            s_wall = (self.wall_z - o[2]) / ray[2]
            s_ground = (self.ground_y - o[1]) / ray[1]
        s_wall[~(s_wall > 0)] = np.inf
        s_ground[~(s_ground > 0)] = np.inf
        on_wall = s_wall <= s_ground
        img = np.zeros((H, W, 3), np.float32)
        # texture coordinates: the wall's (x, y), the ground's (x, z)
        for mask, dist, tex, (a0, b0), (ia, ib) in (
            (on_wall, s_wall, self.wall_texture, self.wall_origin, (0, 1)),
            (~on_wall, s_ground, self.ground_texture, self.ground_origin, (0, 2)),
        ):
            # rays that miss this surface: inf * 0 = NaN, mapped off-texture
            with np.errstate(invalid="ignore"):
                mapx = np.nan_to_num(
                    (o[ia] + dist * ray[ia] - a0) / self.texel, posinf=-1, neginf=-1
                ).astype(np.float32)
                mapy = np.nan_to_num(
                    (o[ib] + dist * ray[ib] - b0) / self.texel, posinf=-1, neginf=-1
                ).astype(np.float32)
            sampled = cv2.remap(tex, mapx, mapy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
            np.copyto(img, sampled.astype(np.float32), where=mask[..., None])
        return cv2.resize(img, (cam.width, cam.height), interpolation=cv2.INTER_AREA)


def make_texture(
    rng: np.random.Generator, height: int, width: int, tint: tuple[float, float, float]
) -> np.ndarray:
    """(height, width, 3) uint8 BGR texture: multi-octave value noise plus random rectangles,
    ellipses and lines (corners for Shi-Tomasi), tinted by `tint` (low chroma, no red)."""
    grey = np.zeros((height, width), np.float32)
    for cell, amp in ((64, 50.0), (16, 35.0), (4, 20.0)):
        coarse = rng.uniform(-1, 1, (max(height // cell, 2), max(width // cell, 2))).astype(
            np.float32
        )
        grey += amp * cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC)
    grey += 120.0
    n_shapes = max(int(height * width / 4000), 4)
    for _ in range(n_shapes):
        level = float(rng.uniform(20, 235))
        x, y = int(rng.integers(0, width)), int(rng.integers(0, height))
        size = int(rng.integers(4, 30))
        kind = rng.integers(0, 3)
        if kind == 0:
            cv2.rectangle(grey, (x, y), (x + size, y + int(rng.integers(4, 30))), level, -1)
        elif kind == 1:
            cv2.ellipse(
                grey,
                (x, y),
                (size, int(rng.integers(3, 20))),
                float(rng.uniform(0, 180)),
                0,
                360,
                level,
                -1,
            )
        else:
            cv2.line(
                grey,
                (x, y),
                (x + int(rng.integers(-40, 40)), y + int(rng.integers(-40, 40))),
                level,
                2,
            )
    grey = np.clip(grey, 0, 255)
    tint = np.asarray(tint, np.float32)
    return np.clip(grey[..., None] * tint[None, None, :], 0, 255).astype(np.uint8)


def disk_coverage(
    camera: PinholeCamera,
    centre: np.ndarray,
    normal: np.ndarray,
    radius: float,
    subsamples: int = 8,
) -> np.ndarray:
    """(H,W) float32 fraction of each pixel covered by the disk (camera-frame centre (3,), unit
    normal (3,), radius), from subsamples^2 rays per pixel intersected with the disk plane
    (exact up to the sampling; only the disk's bounding box is sampled)."""
    cov = np.zeros((camera.height, camera.width), np.float32)
    rim, visible = render_circle_rim(camera, centre, normal, radius, n_points=64)
    if not visible.any():
        return cov
    rim = rim[np.isfinite(rim).all(axis=1)]
    x0, y0 = np.maximum(np.floor(rim.min(axis=0)).astype(int) - 2, 0)
    x1, y1 = np.minimum(np.ceil(rim.max(axis=0)).astype(int) + 3, (camera.width, camera.height))
    if x1 <= x0 or y1 <= y0:
        return cov
    k = int(subsamples)
    offs = (np.arange(k) + 0.5) / k - 0.5
    us = ((np.arange(x0, x1)[:, None] + offs).ravel() - camera.cx) / camera.fx
    vs = ((np.arange(y0, y1)[:, None] + offs).ravel() - camera.cy) / camera.fy
    gu, gv = np.meshgrid(us, vs)
    denom = normal[0] * gu + normal[1] * gv + normal[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = (normal @ centre) / denom  # ray (u, v, 1) meets the plane at this z
    px, py, pz = depth * gu - centre[0], depth * gv - centre[1], depth - centre[2]
    inside = (depth > 0) & (px * px + py * py + pz * pz <= radius * radius)
    cov[y0:y1, x0:x1] = inside.reshape(y1 - y0, k, x1 - x0, k).mean(axis=(1, 3))
    return cov
