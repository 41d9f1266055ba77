"""Feature detection and tracking for motion and structure (seed 003 section II-B-1, eqs. 5-7):
cv2.goodFeaturesToTrack (Shi-Tomasi, eq. 5) and cv2.calcOpticalFlowPyrLK (eq. 7) forward and
backward, a track kept only if it returns within `fb_threshold` px (Kalal et al. 2010).
Pixels are float64 (M,2) (u, v); track ids int64, unique over a tracker's lifetime.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from graphloc.vision.images import check_image, check_points, opencv_errors


@config_dataclass
class FeatureConfig:
    """max_features: tracks kept alive (new corners are detected when fewer survive).
    quality_level, min_distance [px], block_size [px]: cv2.goodFeaturesToTrack (quality_level
    is the eq. 5 threshold lambda relative to the best corner's min eigenvalue).
    win_size [px], max_level (pyramid levels), iterations / epsilon: cv2.calcOpticalFlowPyrLK.
    fb_threshold [px]: forward-backward error above which a track is dropped.
    border [px]: corners and tracks this close to the image edge are not used."""

    max_features: int = setting(20, ge=0)
    quality_level: float = setting(0.01, gt=0.0, lt=1.0)
    min_distance: float = setting(12.0, ge=0.0)
    block_size: int = setting(7, ge=3)
    win_size: int = setting(21, ge=3)
    max_level: int = setting(3, ge=0)
    iterations: int = setting(30, ge=1)
    epsilon: float = setting(0.01, gt=0.0)
    fb_threshold: float = setting(0.5, gt=0.0)
    border: int = setting(10, ge=0)


def as_gray(image: np.ndarray, name: str = "image") -> np.ndarray:
    """uint8 grey image (H,W) from a non-empty (H,W) grey or (H,W,3) BGR uint8 image; ValueError
    naming `name` on anything else (`vision.images.check_image`)."""
    image = check_image(image, name)
    if image.ndim == 3:
        with opencv_errors(f"{name}: BGR to grey"):
            return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return image


def _inside(points: np.ndarray, shape: tuple[int, int], border: float) -> np.ndarray:
    h, w = shape
    with np.errstate(invalid="ignore"):
        return (
            np.isfinite(points).all(axis=1)
            & (points[:, 0] >= border)
            & (points[:, 0] <= w - 1 - border)
            & (points[:, 1] >= border)
            & (points[:, 1] <= h - 1 - border)
        )


def detect_corners(
    gray: np.ndarray,
    max_corners: int,
    config: FeatureConfig = FeatureConfig(),
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Up to `max_corners` Shi-Tomasi corners (M,2), strongest first, outside `mask` == 0 areas
    and `config.border` px from the edge."""
    gray = as_gray(gray, "gray")
    if max_corners <= 0:
        return np.zeros((0, 2))
    allowed = np.zeros(gray.shape, np.uint8)
    b = int(config.border)
    allowed[b : gray.shape[0] - b, b : gray.shape[1] - b] = 255
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != gray.shape:
            raise ValueError(f"detect_corners: mask shape {mask.shape} != image shape {gray.shape}")
        allowed[mask == 0] = 0
    with opencv_errors(f"detect_corners on a {gray.shape[1]}x{gray.shape[0]} image"):
        corners = cv2.goodFeaturesToTrack(
            gray,
            int(max_corners),
            config.quality_level,
            config.min_distance,
            mask=allowed,
            blockSize=config.block_size,
            useHarrisDetector=False,
        )
    return np.zeros((0, 2)) if corners is None else corners.reshape(-1, 2).astype(float)


def track_forward_backward(
    prev_gray: np.ndarray,
    gray: np.ndarray,
    points: np.ndarray,
    config: FeatureConfig = FeatureConfig(),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pyramidal KLT of `points` (M,2) from prev_gray to gray and back. Returns new pixels (M,2)
    (NaN where lost), ok (M,) and the forward-backward error (M,) [px] (inf where LK failed)."""
    prev_gray, gray = as_gray(prev_gray, "prev_gray"), as_gray(gray, "gray")
    if prev_gray.shape != gray.shape:
        raise ValueError(
            f"track_forward_backward: image shapes differ {prev_gray.shape} vs {gray.shape}"
        )
    points = check_points(points, "track_forward_backward: points", flat_ok=True)
    M = len(points)
    if M == 0:
        return np.zeros((0, 2)), np.zeros(0, bool), np.zeros(0)
    lk = dict(
        winSize=(config.win_size, config.win_size),
        maxLevel=config.max_level,
        criteria=(
            cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
            config.iterations,
            config.epsilon,
        ),
    )
    p0 = points.astype(np.float32).reshape(-1, 1, 2)
    with opencv_errors(f"track_forward_backward on {gray.shape[1]}x{gray.shape[0]} images"):
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(prev_gray, gray, p0, None, **lk)
        p0b, st2, _ = cv2.calcOpticalFlowPyrLK(gray, prev_gray, p1, None, **lk)
    p1 = p1.reshape(-1, 2).astype(float)
    fb = np.linalg.norm(p0b.reshape(-1, 2).astype(float) - points, axis=1)
    lk_ok = (st1.reshape(-1) == 1) & (st2.reshape(-1) == 1)
    fb[~lk_ok] = np.inf
    ok = lk_ok & (fb < config.fb_threshold) & _inside(p1, gray.shape, config.border)
    p1[~ok] = np.nan
    return p1, ok, fb


@dataclass(frozen=True)
class FrameFeatures:
    """Features of one frame: ids (M,) int64 and pixels (M,2); n_lost: tracks dropped at this
    frame (LK failure, forward-backward error, border, or entering the exclusion mask);
    n_new: tracks started at this frame."""

    ids: np.ndarray
    pixels: np.ndarray
    n_lost: int = 0
    n_new: int = 0


class FeatureTracker:
    """Keeps up to `config.max_features` KLT tracks alive over a frame stream.

    tracker = FeatureTracker(FeatureConfig(max_features=9))
    for image, exclude in frames:      # exclude: (H,W) mask, nonzero = no features (e.g. a robot)
        f = tracker.step(image, exclude)   # FrameFeatures(ids, pixels)
    """

    def __init__(self, config: FeatureConfig = FeatureConfig()):
        self.config = config
        self._prev: np.ndarray | None = None
        self._ids = np.zeros(0, np.int64)
        self._pixels = np.zeros((0, 2))
        self._next_id = 0
        self.n_frames = 0

    def step(self, image: np.ndarray, exclude: np.ndarray | None = None) -> FrameFeatures:
        gray = as_gray(image)
        if self._prev is not None and self._prev.shape != gray.shape:
            raise ValueError(
                f"FeatureTracker.step: frame {self.n_frames} has shape {gray.shape}, "
                f"previous frames {self._prev.shape}"
            )
        if exclude is not None:
            exclude = np.asarray(exclude)
            if exclude.shape != gray.shape:
                raise ValueError(
                    f"FeatureTracker.step: exclude mask shape {exclude.shape} != image {gray.shape}"
                )
        n_lost = 0
        if self._prev is not None and len(self._ids):
            pixels, ok, _ = track_forward_backward(self._prev, gray, self._pixels, self.config)
            if exclude is not None:
                iu = np.clip(
                    np.rint(np.nan_to_num(pixels)).astype(int),
                    0,
                    [gray.shape[1] - 1, gray.shape[0] - 1],
                )
                ok &= exclude[iu[:, 1], iu[:, 0]] == 0
            n_lost = int((~ok).sum())
            self._ids, self._pixels = self._ids[ok], pixels[ok]
        n_new = 0
        want = int(self.config.max_features) - len(self._ids)
        if want > 0:
            allowed = np.full(gray.shape, 255, np.uint8)
            if exclude is not None:
                allowed[exclude != 0] = 0
            for u, v in np.rint(self._pixels).astype(int):  # keep new corners away from live tracks
                cv2.circle(allowed, (int(u), int(v)), int(max(self.config.min_distance, 1)), 0, -1)
            corners = detect_corners(gray, want, self.config, allowed)
            n_new = len(corners)
            self._ids = np.concatenate(
                [self._ids, np.arange(self._next_id, self._next_id + n_new, dtype=np.int64)]
            )
            self._pixels = np.vstack([self._pixels, corners])
            self._next_id += n_new
        self._prev = gray
        self.n_frames += 1
        return FrameFeatures(self._ids.copy(), self._pixels.copy(), n_lost, n_new)
