"""Blob extraction for identical spherical markers (active LEDs or passive paint), seed 001
(001_0f8f8dae37ce6b79.txt) section IV-B "Blob extraction": Otsu threshold F1, outlier
rejection, the looser histogram threshold F2 inside the survivors' window, a second rejection,
merging or Hough recovery to the expected count, sub-pixel centroids from intensity-weighted
moments; colour markers in YUV. An optional region of interest restricts all work. Never
silently returns fewer blobs than expected (`MarkerDetections.shortfall`, status "shortfall").
"""

from __future__ import annotations

import warnings

import cv2
import numpy as np
from scipy.optimize import OptimizeWarning, curve_fit

from graphloc.vision.blob_recovery import hough_blobs, reduce_blobs
from graphloc.vision.blobs import Blobs, label_stats, reject, window_cut
from graphloc.vision.images import check_image, check_points, opencv_errors
from graphloc.vision.marker_config import MarkerDetections, MarkerDetectorConfig

# ----------------------------------------------------------------------------- foreground


def marker_likeness(image: np.ndarray, config: MarkerDetectorConfig) -> np.ndarray:
    """uint8 image in which markers are bright: grey as-is, inverted grey, or YUV chroma likeness.
    ValueError (via `vision.images.check_image`) unless image is a non-empty uint8 (H,W) or
    (H,W,3) BGR array ((H,W,3) only for polarity 'color')."""
    if config.polarity == "color":
        img = check_image(image, "marker image (polarity 'color', BGR)", channels=(3,))
        with opencv_errors("marker_likeness"):
            yuv = cv2.cvtColor(img, cv2.COLOR_BGR2YUV).astype(np.float32)
        _, u0, v0 = config.marker_yuv
        dist = np.hypot(yuv[..., 1] - u0, yuv[..., 2] - v0)
        like = np.clip(255.0 - config.uv_scale * dist, 0.0, 255.0)
        like[yuv[..., 0] < config.min_luma] = 0.0
        return like.astype(np.uint8)
    img = check_image(image, "marker image")
    if img.ndim == 3:
        with opencv_errors("marker_likeness"):
            img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    return img if config.polarity == "bright" else (255 - img)


def _gaussian(x, a, mu, sigma):
    return a * np.exp(-0.5 * ((x - mu) / sigma) ** 2)


def background_gaussian(gray: np.ndarray) -> tuple[float, float]:
    """(mean, std) of a Gaussian fitted to the grey-level histogram (seed 001 IV-B, F2).

    Background pixels dominate, so the fit around the histogram mode describes the background.
    """
    hist = np.bincount(gray.ravel(), minlength=256).astype(float)
    x = np.arange(256, dtype=float)
    mode = float(np.argmax(hist))
    half = hist >= 0.5 * hist.max()
    sigma0 = max(0.5, (np.flatnonzero(half).max() - np.flatnonzero(half).min() + 1) / 2.355)
    sel = np.abs(x - mode) <= max(3.0, 4.0 * sigma0)
    if sel.sum() < 4:
        return mode, sigma0
    try:
        with warnings.catch_warnings():  # a one-bin histogram (noise-free frame) has no covariance
            warnings.simplefilter("ignore", OptimizeWarning)
            (_, mu, sigma), _ = curve_fit(
                _gaussian, x[sel], hist[sel], p0=(hist.max(), mode, sigma0), maxfev=200
            )
    except RuntimeError:
        return mode, sigma0
    if not (np.isfinite(mu) and np.isfinite(sigma)) or abs(mu - mode) > 4.0 * sigma0 + 1.0:
        return mode, sigma0
    return float(mu), max(0.5, abs(float(sigma)))


# ----------------------------------------------------------------------------- pipeline


def _detect_in_region(gray, region, config, predicted_px, steps, counts):
    x0, y0, x1, y1 = region
    sub = gray[y0:y1, x0:x1]
    mu, sigma = background_gaussian(sub)
    f2 = min(254.0, mu + config.f2_sigmas * sigma)
    otsu, _ = cv2.threshold(sub, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    f1 = max(float(otsu), f2)  # Otsu on a marker-free window would split the noise
    weight = np.clip(
        sub.astype(np.float32) - mu, 0.0, None
    )  # region only: an ROI restricts all work

    h, w = gray.shape
    blobs1, labels1 = label_stats(sub > f1, weight, (x0, y0))
    blobs1 = reject(
        blobs1,
        labels1,
        (x0, y0),
        config,
        counts,
        exclude=window_cut(blobs1.box, region, w, h, counts),
    )
    if len(blobs1):
        m = config.window_margin
        wx0, wy0 = (
            max(x0, int(blobs1.box[:, 0].min()) - m),
            max(y0, int(blobs1.box[:, 1].min()) - m),
        )
        wx1, wy1 = (
            min(x1, int(blobs1.box[:, 2].max()) + m),
            min(y1, int(blobs1.box[:, 3].max()) + m),
        )
        mask2 = gray[wy0:wy1, wx0:wx1] > f2
        blobs, labels2 = label_stats(
            mask2, weight[wy0 - y0 : wy1 - y0, wx0 - x0 : wx1 - x0], (wx0, wy0)
        )
        window = (wx0, wy0, wx1, wy1)
        blobs = reject(
            blobs,
            labels2,
            (wx0, wy0),
            config,
            counts,
            exclude=window_cut(blobs.box, window, w, h, counts),
        )
    else:
        mask2, blobs, window = None, Blobs.empty(), region

    if len(blobs) < config.expected and mask2 is not None and config.erosion_iterations > 0:
        # erosion by a Euclidean disc of growing radius (distance transform), splits touching
        # markers
        depth = cv2.distanceTransform(mask2.astype(np.uint8), cv2.DIST_L2, 5)
        r_big = blobs.radii().max() if len(blobs) else 0.0
        n_erode = max(
            config.erosion_iterations, int(np.ceil(config.erosion_radius_fraction * r_big))
        )
        for it in range(1, n_erode + 1):
            eroded = depth > it
            eb, el = label_stats(
                eroded, weight[wy0 - y0 : wy1 - y0, wx0 - x0 : wx1 - x0], (wx0, wy0)
            )
            # the same window-cut rule as the F2 pass: distanceTransform treats pixels beyond the
            # crop as foreground, so a fragment cut by the window does not shrink from that side
            eb = reject(
                eb, el, (wx0, wy0), config, {}, exclude=window_cut(eb.box, window, w, h, {})
            )
            if len(eb) > len(blobs):
                blobs = eb
                steps.append("erosion")
            if len(blobs) >= config.expected:
                break
    if len(blobs) < config.expected and config.hough:
        extra = hough_blobs(gray, region, blobs, mu, sigma, config, counts)
        if len(extra):
            blobs = blobs.concat(extra)
            steps.append("hough")
    if len(blobs) > config.expected:
        blobs = reduce_blobs(blobs, config.expected, config, predicted_px, steps)
    return blobs, (f1, f2)


def detect_markers(
    image: np.ndarray,
    config: MarkerDetectorConfig = MarkerDetectorConfig(),
    roi: tuple[int, int, int, int] | None = None,
    predicted_px: np.ndarray | None = None,
) -> MarkerDetections:
    """Detect `config.expected` identical marker blobs (seed 001 IV-B).

    image: (H,W) uint8 grey or (H,W,3) uint8 BGR. roi: (x0, y0, x1, y1) to search first (e.g.
    `roi_from_points(predicted_px, ...)`); if it yields a shortfall and `full_image_fallback`,
    the whole image is searched again. predicted_px: (k,2) predicted marker pixels used to pick
    the false positives to drop. Returns MarkerDetections (check `.status` / `.shortfall`).
    """
    gray = marker_likeness(image, config)
    h, w = gray.shape
    full = (0, 0, w, h)
    if predicted_px is not None:
        pred = check_points(predicted_px, "detect_markers: predicted_px", flat_ok=True)
        predicted_px = pred
    if roi is not None:
        try:
            box = np.asarray(roi, dtype=float).reshape(4)
        except (TypeError, ValueError):
            raise ValueError(
                f"detect_markers: roi must be 4 numbers (x0, y0, x1, y1), got {roi!r}"
            ) from None
        if not np.isfinite(box).all():
            raise ValueError(f"detect_markers: roi {roi} is not finite")
        x0, y0, x1, y1 = (int(v) for v in np.clip(box, -1, max(w, h) + 1))
        x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w, x1), min(h, y1)
        if x1 - x0 < 2 or y1 - y0 < 2:
            raise ValueError(f"detect_markers: roi {roi} is empty inside the {w}x{h} image")
        region = (x0, y0, x1, y1)
    else:
        region = full
    steps: list[str] = []
    counts: dict = {}
    with opencv_errors(f"detect_markers on a {w}x{h} image"):
        blobs, thr = _detect_in_region(gray, region, config, predicted_px, steps, counts)
    if len(blobs) < config.expected and region != full and config.full_image_fallback:
        steps.append("full_image")
        with opencv_errors(f"detect_markers on a {w}x{h} image"):
            blobs_full, thr_full = _detect_in_region(
                gray, full, config, predicted_px, steps, counts
            )
        if len(blobs_full) > len(blobs):
            blobs, thr = blobs_full, thr_full
    return MarkerDetections(
        points=blobs.centroids(),
        scores=blobs.scores(),
        radii=blobs.radii(),
        areas=blobs.n.copy(),
        expected=config.expected,
        thresholds=(float(thr[0]), float(thr[1])),
        steps=tuple(steps),
        roi=None if region == full else region,
        rejected=counts,
    )
