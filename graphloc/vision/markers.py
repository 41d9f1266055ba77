"""Blob extraction for identical spherical markers (active LEDs or passive paint).

Seed 001 (seeds/001_0f8f8dae37ce6b79.txt), section IV-B "Blob extraction":
Otsu threshold F1 locates blobs; first outlier rejection (size, non-convexity, eccentricity);
the looser threshold F2 (a Gaussian fitted to the grey-level histogram, F2 at a multiple of its
standard deviation) refines the blobs inside the window enclosing the survivors; second
rejection; too many blobs -> merge the closest pair or remove the blob farthest from the others;
too few -> erosion, then circular Hough transform; sub-pixel centroids from intensity-weighted
moments. Colour markers: the foreground is computed in YUV so chroma is decoupled from
brightness (seed 001 IV-B, last paragraph). An optional region of interest (from a predicted
pose, see `graphloc.vision.target.predicted_marker_pixels`) restricts all work.

Never silently returns fewer blobs than expected: `MarkerDetections.shortfall` says how many are
missing and `status` is "shortfall".
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import OptimizeWarning, curve_fit

from graphloc.config import check
from graphloc.vision.images import check_image, check_points, opencv_errors

POLARITIES = ("bright", "dark", "color")


@dataclass(frozen=True)
class MarkerDetectorConfig:
    """Parameters of the seed-001 blob extraction (pixels and 8-bit grey levels).

    polarity: "bright" (active LEDs, light paint on dark ground), "dark" (dark paint on light
    ground, thresholds computed inversely) or "color" (YUV chroma distance to `marker_yuv`).
    """

    expected: int = 4
    polarity: str = "bright"
    marker_yuv: tuple[float, float, float] = (0.0, 128.0, 128.0)
    uv_scale: float = 3.0  # likeness grey levels lost per unit of UV distance (colour only)
    min_luma: float = 30.0  # colour only: darker pixels are never markers
    min_area: int = 4
    max_area: int = 20000
    min_axis_ratio: float = 0.4  # minor/major axis of the blob's second moments
    min_solidity: float = 0.75  # area / convex-hull area
    f2_sigmas: float = 4.0  # F2 = mean + f2_sigmas * std of the fitted background Gaussian
    window_margin: int = 6
    merge_factor: float = 1.5  # merge the closest pair if closer than factor * (r_i + r_j)
    erosion_iterations: int = 2  # erode by discs of radius 1, 2, ... at least this many ...
    erosion_radius_fraction: float = 0.6  # ... and up to this fraction of the largest blob radius
    hough: bool = True
    hough_min_radius: int = 2
    hough_max_radius: int = 40
    hough_perfectness: float = 0.5  # param2 of cv2.HOUGH_GRADIENT_ALT
    full_image_fallback: bool = True  # ROI failed -> search the whole image (seed IV-B)

    def __post_init__(self):
        check(
            self,
            choices={"polarity": POLARITIES},
            integer={"expected": 1},
            interval={
                "min_area": (0.0, "max_area", "(]"),
                "min_axis_ratio": (0.0, 1.0, "[]"),
                "min_solidity": (0.0, 1.0, "[]"),
            },
        )


@dataclass(frozen=True)
class MarkerDetections:
    """Detected marker blobs of one frame.

    points: (M,2) sub-pixel centroids (x, y) in full-image pixel coordinates.
    scores: (M,) shape quality in [0,1] (axis ratio x solidity; Hough-recovered blobs x 0.5).
    radii: (M,) equivalent radius sqrt(area/pi) [px]. areas: (M,) pixel counts.
    expected: number of markers asked for. thresholds: (F1, F2) on the marker-likeness image.
    steps: recovery / reduction steps applied, in order ("merge", "remove", "erosion", "hough",
    "full_image"). roi: (x0, y0, x1, y1) searched first, or None for the whole image.
    """

    points: np.ndarray
    scores: np.ndarray
    radii: np.ndarray
    areas: np.ndarray
    expected: int
    thresholds: tuple[float, float]
    steps: tuple[str, ...] = ()
    roi: tuple[int, int, int, int] | None = None
    rejected: dict = field(default_factory=dict, compare=False)

    @property
    def shortfall(self) -> int:
        return max(0, self.expected - len(self.points))

    @property
    def status(self) -> str:
        return "ok" if self.shortfall == 0 else "shortfall"

    def __len__(self) -> int:
        return len(self.points)


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


# ----------------------------------------------------------------------------- blob statistics


@dataclass
class _Blobs:
    """Additive raw moments of blobs (rows), so merging two blobs is a row sum."""

    n: np.ndarray  # pixel count
    s: np.ndarray  # (B,5) binary sums x, y, xx, yy, xy
    w: np.ndarray  # (B,3) weighted sums w, wx, wy
    box: np.ndarray  # (B,4) x0, y0, x1, y1 (exclusive)
    solidity: np.ndarray
    hough: np.ndarray  # bool: recovered by Hough

    def __len__(self):
        return len(self.n)

    @staticmethod
    def empty() -> "_Blobs":
        return _Blobs(
            np.zeros(0),
            np.zeros((0, 5)),
            np.zeros((0, 3)),
            np.zeros((0, 4), int),
            np.zeros(0),
            np.zeros(0, bool),
        )

    def take(self, idx) -> "_Blobs":
        return _Blobs(
            self.n[idx],
            self.s[idx],
            self.w[idx],
            self.box[idx],
            self.solidity[idx],
            self.hough[idx],
        )

    def concat(self, other: "_Blobs") -> "_Blobs":
        return _Blobs(
            *(
                np.concatenate([a, b])
                for a, b in zip(
                    (self.n, self.s, self.w, self.box, self.solidity, self.hough),
                    (other.n, other.s, other.w, other.box, other.solidity, other.hough),
                )
            )
        )

    def centroids(self) -> np.ndarray:
        """Intensity-weighted centroids; binary centroid where the weights vanish."""
        binary = self.s[:, :2] / np.maximum(self.n, 1)[:, None]
        wsum = self.w[:, 0:1]
        weighted = self.w[:, 1:3] / np.where(wsum > 0, wsum, 1.0)
        return np.where(wsum > 0, weighted, binary)

    def axis_ratio(self) -> np.ndarray:
        """sqrt(minor/major eigenvalue) of the binary second central moments (+1/12 pixel
        extent)."""
        n = np.maximum(self.n, 1)
        mx, my = self.s[:, 0] / n, self.s[:, 1] / n
        cxx = self.s[:, 2] / n - mx * mx + 1.0 / 12
        cyy = self.s[:, 3] / n - my * my + 1.0 / 12
        cxy = self.s[:, 4] / n - mx * my
        tr, det = cxx + cyy, cxx * cyy - cxy * cxy
        disc = np.sqrt(np.maximum(tr * tr / 4 - det, 0.0))
        lmax, lmin = tr / 2 + disc, np.maximum(tr / 2 - disc, 0.0)
        return np.sqrt(lmin / np.maximum(lmax, 1e-12))

    def radii(self) -> np.ndarray:
        return np.sqrt(self.n / np.pi)

    def scores(self) -> np.ndarray:
        return np.clip(self.axis_ratio() * self.solidity, 0.0, 1.0) * np.where(self.hough, 0.5, 1.0)

    def merge(self, i: int, j: int) -> "_Blobs":
        keep = [k for k in range(len(self)) if k not in (i, j)]
        box = np.concatenate(
            [
                np.minimum(self.box[i, :2], self.box[j, :2]),
                np.maximum(self.box[i, 2:], self.box[j, 2:]),
            ]
        )
        merged = _Blobs(
            np.array([self.n[i] + self.n[j]]),
            (self.s[i] + self.s[j])[None],
            (self.w[i] + self.w[j])[None],
            box[None],
            np.array([min(self.solidity[i], self.solidity[j])]),
            np.array([self.hough[i] or self.hough[j]]),
        )
        return self.take(keep).concat(merged)


def _label_stats(
    mask: np.ndarray, weight: np.ndarray, origin: tuple[int, int]
) -> tuple[_Blobs, np.ndarray]:
    """Connected components of `mask` (a window at `origin`=(x0,y0)) -> moments of every blob
    (vectorized)."""
    n_lab, labels, stats, _ = cv2.connectedComponentsWithStats(
        mask.astype(np.uint8), connectivity=8
    )
    return _stats_from_labels(labels, n_lab, stats[:, :4], weight, origin), labels


def _stats_from_labels(labels, n_lab, bbox_xywh, weight, origin) -> _Blobs:
    x0, y0 = origin
    fg = labels > 0
    lab = labels[fg] - 1
    ys, xs = np.nonzero(fg)
    xs = xs.astype(float) + x0
    ys = ys.astype(float) + y0
    w = weight[fg].astype(float)
    B = n_lab - 1
    cnt = np.bincount(lab, minlength=B).astype(float)
    s = np.stack(
        [np.bincount(lab, v, minlength=B) for v in (xs, ys, xs * xs, ys * ys, xs * ys)], axis=1
    )
    ws = np.stack([np.bincount(lab, v, minlength=B) for v in (w, w * xs, w * ys)], axis=1)
    bb = np.asarray(bbox_xywh[1:], dtype=int).reshape(B, 4)
    box = np.stack(
        [bb[:, 0] + x0, bb[:, 1] + y0, bb[:, 0] + bb[:, 2] + x0, bb[:, 1] + bb[:, 3] + y0], axis=1
    )
    return _Blobs(cnt, s.reshape(B, 5), ws.reshape(B, 3), box, np.ones(B), np.zeros(B, bool))


def _solidity(labels: np.ndarray, label: int, box_local: np.ndarray) -> float:
    """Contour area / convex-hull area of one labelled blob (1 for blobs too small to tell)."""
    x0, y0, x1, y1 = box_local
    crop = (labels[y0:y1, x0:x1] == label).astype(np.uint8)
    contours, _ = cv2.findContours(crop, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    contour = max(contours, key=len)
    hull_area = cv2.contourArea(cv2.convexHull(contour))
    if hull_area < 4.0:
        return 1.0
    return float(cv2.contourArea(contour) / hull_area)


def _reject(
    blobs: _Blobs,
    labels: np.ndarray,
    origin,
    config: MarkerDetectorConfig,
    counts: dict,
    exclude: np.ndarray | None = None,
) -> _Blobs:
    """Outlier rejection of seed 001 IV-B: too small / too large, eccentric, non-convex
    (blobs flagged in `exclude` are dropped first)."""
    excluded = np.zeros(len(blobs), bool) if exclude is None else exclude
    size_ok = (blobs.n >= config.min_area) & (blobs.n <= config.max_area)
    counts["size"] = counts.get("size", 0) + int((~size_ok & ~excluded).sum())
    size_ok &= ~excluded
    shape_ok = blobs.axis_ratio() >= config.min_axis_ratio
    counts["eccentric"] = counts.get("eccentric", 0) + int((size_ok & ~shape_ok).sum())
    idx = np.flatnonzero(size_ok & shape_ok)
    x0, y0 = origin
    sol = np.array(
        [_solidity(labels, i + 1, blobs.box[i] - [x0, y0, x0, y0]) for i in idx], dtype=float
    )
    blobs.solidity[idx] = sol
    convex = sol >= config.min_solidity
    counts["non_convex"] = counts.get("non_convex", 0) + int((~convex).sum())
    return blobs.take(idx[convex])


# ----------------------------------------------------------------------------- pipeline


def marker_area_bounds(
    focal_px: float, marker_radius: float, min_range: float, max_range: float, slack: float = 2.0
) -> tuple[int, int]:
    """(min_area, max_area) [px] of a sphere of radius `marker_radius` seen from `min_range` to
    `max_range` [m] with focal length `focal_px`, widened by `slack` in radius (blur, threshold)."""
    if not (0 < marker_radius < min_range <= max_range) or focal_px <= 0 or slack < 1:
        raise ValueError(
            f"marker_area_bounds: need 0 < marker_radius < min_range <= max_range, focal > 0, "
            f"slack >= 1; got {marker_radius}, {min_range}, {max_range}, {focal_px}, {slack}"
        )
    r_far = focal_px * np.tan(np.arcsin(marker_radius / max_range))
    r_near = focal_px * np.tan(np.arcsin(marker_radius / min_range))
    return max(1, int(np.floor(np.pi * (r_far / slack) ** 2))), int(
        np.ceil(np.pi * (r_near * slack) ** 2)
    )


def roi_from_points(
    points_px: np.ndarray, margin: float, shape: tuple[int, int]
) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) window around predicted marker pixels, `margin` px wide, clipped to the
    image."""
    p = np.asarray(points_px, dtype=float).reshape(-1, 2)
    if len(p) == 0 or not np.isfinite(p).all():
        raise ValueError(f"roi_from_points: predicted pixels must be finite (M,2), got {p.shape}")
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError(f"roi_from_points: margin must be finite and >= 0, got {margin}")
    h, w = shape[:2]
    x0 = int(np.clip(np.floor(p[:, 0].min() - margin), 0, w))
    y0 = int(np.clip(np.floor(p[:, 1].min() - margin), 0, h))
    x1 = int(np.clip(np.ceil(p[:, 0].max() + margin) + 1, 0, w))
    y1 = int(np.clip(np.ceil(p[:, 1].max() + margin) + 1, 0, h))
    return x0, y0, x1, y1


def _cut(box: np.ndarray, window, width: int, height: int, counts: dict) -> np.ndarray:
    """Blobs touching an edge of the search window that is not an image edge continue outside
    it: fragments (of clutter or of a marker), never accepted as markers."""
    x0, y0, x1, y1 = window
    cut = (
        ((box[:, 0] <= x0) & (x0 > 0))
        | ((box[:, 1] <= y0) & (y0 > 0))
        | ((box[:, 2] >= x1) & (x1 < width))
        | ((box[:, 3] >= y1) & (y1 < height))
    )
    counts["window_cut"] = counts.get("window_cut", 0) + int(cut.sum())
    return cut


def _reduce(
    blobs: _Blobs, expected: int, config: MarkerDetectorConfig, predicted_px, steps: list
) -> _Blobs:
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


def _hough_blobs(gray, region, known: _Blobs, mu, sigma, config, counts) -> _Blobs:
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
        return _Blobs.empty()
    circ = circles.reshape(-1, circles.shape[-1])[:, :3].astype(float)
    circ[:, :2] += (x0, y0)
    if len(known):
        dk = np.linalg.norm(circ[:, None, :2] - known.centroids()[None], axis=2)
        circ = circ[(dk > (circ[:, 2:3] + known.radii()[None])).all(axis=1)]
    if len(circ) == 0:
        return _Blobs.empty()
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
    blobs = _stats_from_labels(labels, len(circ) + 1, bbox, weight, (x0, y0))
    blobs.hough[:] = True
    return _reject(blobs, labels, (x0, y0), config, counts)


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
    blobs1, labels1 = _label_stats(sub > f1, weight, (x0, y0))
    blobs1 = _reject(
        blobs1, labels1, (x0, y0), config, counts, exclude=_cut(blobs1.box, region, w, h, counts)
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
        blobs, labels2 = _label_stats(
            mask2, weight[wy0 - y0 : wy1 - y0, wx0 - x0 : wx1 - x0], (wx0, wy0)
        )
        window = (wx0, wy0, wx1, wy1)
        blobs = _reject(
            blobs,
            labels2,
            (wx0, wy0),
            config,
            counts,
            exclude=_cut(blobs.box, window, w, h, counts),
        )
    else:
        mask2, blobs, window = None, _Blobs.empty(), region

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
            eb, el = _label_stats(
                eroded, weight[wy0 - y0 : wy1 - y0, wx0 - x0 : wx1 - x0], (wx0, wy0)
            )
            # the same window-cut rule as the F2 pass: distanceTransform treats pixels beyond the
            # crop as foreground, so a fragment cut by the window does not shrink from that side
            eb = _reject(eb, el, (wx0, wy0), config, {}, exclude=_cut(eb.box, window, w, h, {}))
            if len(eb) > len(blobs):
                blobs = eb
                steps.append("erosion")
            if len(blobs) >= config.expected:
                break
    if len(blobs) < config.expected and config.hough:
        extra = _hough_blobs(gray, region, blobs, mu, sigma, config, counts)
        if len(extra):
            blobs = blobs.concat(extra)
            steps.append("hough")
    if len(blobs) > config.expected:
        blobs = _reduce(blobs, config.expected, config, predicted_px, steps)
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
