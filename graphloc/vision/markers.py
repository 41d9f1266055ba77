"""Blob extraction for identical spherical markers (active LEDs or passive paint), seed 001
(001_0f8f8dae37ce6b79.txt) section IV-B "Blob extraction": Otsu threshold F1, outlier
rejection, the looser histogram threshold F2 inside the survivors' window, a second rejection,
merging or Hough recovery to the expected count (too many blobs: merge the closest pair or
remove the blob farthest from the others, `reduce_blobs`; too few: circular Hough transform,
`hough_blobs`), sub-pixel centroids from intensity-weighted
moments; colour markers in YUV. An optional region of interest restricts all work. Never
silently returns fewer blobs than expected (`MarkerDetections.shortfall`, status "shortfall").
"""

from __future__ import annotations

import warnings

import cv2
import numpy as np
from scipy.optimize import OptimizeWarning, curve_fit

from graphloc.vision.blobs import Blobs, label_stats, reject, stats_from_labels, window_cut
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


def reduce_blobs(
    blobs: Blobs, expected: int, config: MarkerDetectorConfig, predicted_px, steps: list
) -> Blobs:
    """Too many blobs (seed 001 IV-B): merge the two closest if they touch (fragments of one
    marker), else remove the blob with the largest summed distance to all the others. With
    predicted marker pixels (the seed's alternative), the blob farthest from every prediction is
    removed first, and only blobs near predictions are merged.
    """
    while len(blobs) > expected:
        c = blobs.centroids()
        r = blobs.radii()
        d = np.linalg.norm(c[:, None] - c[None], axis=2)
        np.fill_diagonal(d, np.inf)
        i, j = np.unravel_index(np.argmin(d), d.shape)
        mergeable = d[i, j] < config.merge_factor * (r[i] + r[j])
        if predicted_px is not None:
            # with a prediction a blob far from every predicted marker goes first; two markers
            # that happen to lie close together in the image are not merged
            off = np.linalg.norm(c[:, None] - predicted_px[None], axis=2).min(axis=1)
            worst = int(np.argmax(off))
            if not mergeable or off[worst] > config.merge_factor * 2.0 * r.max():
                blobs = blobs.take(np.delete(np.arange(len(blobs)), worst))
                steps.append("remove")
                continue
        elif not mergeable:
            np.fill_diagonal(d, 0.0)
            blobs = blobs.take(np.delete(np.arange(len(blobs)), int(np.argmax(d.sum(axis=1)))))
            steps.append("remove")
            continue
        blobs = blobs.merge(i, j)
        steps.append("merge")
    return blobs


def hough_blobs(gray, region, known: Blobs, mu, sigma, config, counts) -> Blobs:
    """Circular Hough transform recovery: circles away from the known blobs, whose mean contrast
    is at least half the F2 margin above the background, become new blobs."""
    f2_margin = config.f2_sigmas * sigma
    x0, y0, x1, y1 = region
    sub = cv2.GaussianBlur(gray[y0:y1, x0:x1], (5, 5), 1.0)
    if len(known):
        rk = known.radii()
        rmin = max(config.hough_min_radius, int(np.floor(0.5 * rk.min())))
        rmax = min(config.hough_max_radius, int(np.ceil(2.0 * rk.max())) + 1)
    else:
        rmin, rmax = config.hough_min_radius, config.hough_max_radius
    circles = cv2.HoughCircles(
        sub,
        cv2.HOUGH_GRADIENT_ALT,
        dp=1.5,
        minDist=max(2.0, 2.0 * rmin),
        param1=max(10.0, 6.0 * sigma),
        param2=config.hough_perfectness,
        minRadius=rmin,
        maxRadius=max(rmax, rmin + 1),
    )
    if circles is None:
        return Blobs.empty()
    circ = circles.reshape(-1, circles.shape[-1])[:, :3].astype(float)
    circ[:, :2] += (x0, y0)
    if len(known):
        dk = np.linalg.norm(circ[:, None, :2] - known.centroids()[None], axis=2)
        circ = circ[(dk > (circ[:, 2:3] + known.radii()[None])).all(axis=1)]
    if len(circ) == 0:
        return Blobs.empty()
    # label image of the disks (1.5 r + 2 px, so an off-centre circle still covers its blob),
    # thresholded at a looser level than F2 (mean + 2 sigma); numpy on each circle's box only
    h, w = y1 - y0, x1 - x0
    labels = np.zeros((h, w), np.int32)
    fg = gray[y0:y1, x0:x1] > mu + 2.0 * sigma
    bbox = np.zeros((len(circ) + 1, 4), int)
    for k, (cx, cy, r) in enumerate(circ, start=1):
        reach = 1.5 * r + 2.0
        bx0, by0 = max(0, int(cx - reach) - x0), max(0, int(cy - reach) - y0)
        bx1, by1 = min(w, int(cx + reach) + 2 - x0), min(h, int(cy + reach) + 2 - y0)
        yy, xx = np.mgrid[by0:by1, bx0:bx1]
        rr = (xx + x0 - cx) ** 2 + (yy + y0 - cy) ** 2
        disc = rr <= r * r
        if (
            not disc.any()
            or gray[y0 + by0 : y0 + by1, x0 + bx0 : x0 + bx1][disc].mean() - mu < 0.5 * f2_margin
        ):
            counts["hough_low_contrast"] = counts.get("hough_low_contrast", 0) + 1
            continue  # a circle in the noise, not a dim marker
        inside = (rr <= reach**2) & fg[by0:by1, bx0:bx1] & (labels[by0:by1, bx0:bx1] == 0)
        labels[by0:by1, bx0:bx1][inside] = k
        ys, xs = np.nonzero(inside)
        if len(xs):
            bbox[k] = (
                xs.min() + bx0,
                ys.min() + by0,
                xs.max() - xs.min() + 1,
                ys.max() - ys.min() + 1,
            )
    weight = np.clip(gray[y0:y1, x0:x1].astype(float) - mu, 0.0, None)
    blobs = stats_from_labels(labels, len(circ) + 1, bbox, weight, (x0, y0))
    blobs.hough[:] = True
    return reject(blobs, labels, (x0, y0), config, counts)
