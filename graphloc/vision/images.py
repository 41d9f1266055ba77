"""Input checks shared by the vision entry points: `check_image` before any OpenCV call (some
crash or hang on a zero-size image) and `opencv_errors`, which turns a `cv2.error` into a
ValueError naming the caller's argument.
"""

from __future__ import annotations

from contextlib import contextmanager

import cv2
import numpy as np


def check_image(
    image, name: str = "image", channels: tuple[int, ...] = (1, 3), min_size: int = 1
) -> np.ndarray:
    """`image` as a C-contiguous uint8 array of shape (H,W) (allowed when 1 is in `channels`)
    or (H,W,C) with C in `channels` other than 1, H and W >= min_size. ValueError naming
    `name` and what is wrong (type, dtype, shape, size) otherwise."""
    try:
        img = np.asarray(image)
    except (TypeError, ValueError) as exc:  # ragged nested sequences
        raise ValueError(f"{name} is not an array ({exc})") from None
    if img.dtype != np.uint8:
        raise ValueError(f"{name} must be an 8-bit image (dtype uint8), got dtype {img.dtype}")
    colour = tuple(c for c in channels if c != 1)
    allowed = (["(H,W)"] if 1 in channels else []) + [f"(H,W,{c})" for c in colour]
    if not ((img.ndim == 2 and 1 in channels) or (img.ndim == 3 and img.shape[2] in colour)):
        raise ValueError(f"{name} must have shape {' or '.join(allowed)}, got {img.shape}")
    h, w = img.shape[:2]
    if h < min_size or w < min_size:
        raise ValueError(
            f"{name} is {w}x{h} px (width x height); at least {min_size}x{min_size} px needed"
        )
    return np.ascontiguousarray(img)


@contextmanager
def opencv_errors(what: str):
    """Turn a `cv2.error` raised inside the block into a ValueError that starts with `what`
    and carries OpenCV's own reason (the failed check and the OpenCV function)."""
    try:
        yield
    except cv2.error as exc:
        reason = (getattr(exc, "err", "") or str(exc)).strip()
        func = getattr(exc, "func", "")
        raise ValueError(
            f"{what}: OpenCV rejected the input ({reason}{' in ' + func if func else ''})"
        ) from None


def check_points(points, name: str, min_rows: int = 0, flat_ok: bool = False) -> np.ndarray:
    """(M,2) float64 pixel array from `points` (flat_ok: also (2M,) u0, v0, u1, ...); ValueError
    naming `name` when it cannot be one, has fewer than `min_rows` rows or contains NaN/inf."""
    try:
        pts = np.asarray(points, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} is not a numeric array ({exc})") from None
    if flat_ok and pts.ndim == 1 and pts.size % 2 == 0:
        pts = pts.reshape(-1, 2)
    if pts.size == 0 and min_rows == 0:
        return np.zeros((0, 2))
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"{name} must have shape (M,2), got {pts.shape}")
    if len(pts) < min_rows:
        raise ValueError(f"{name} has {len(pts)} points, at least {min_rows} needed")
    bad = np.flatnonzero(~np.isfinite(pts).all(axis=1))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] = {pts[bad[0]]} is not finite")
    return pts
