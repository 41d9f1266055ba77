"""The colour-signature blob rim of the teammate's base (seed 003, 003_8db27855ce2d5f68.txt,
section II-A-1: colour threshold -> median filter -> edge points of the ellipse), optionally
refined by an edge-model fit to the base's coverage map (`graphloc.vision.ellipse.refine_ellipse`).
Pixels are float64 (M,2) (u, v), (0, 0) the centre of the top-left pixel."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from graphloc.vision.ellipse import EllipseRefinement, ellipse_points, fit_ellipse, refine_ellipse
from graphloc.vision.images import check_image, opencv_errors


@config_dataclass
class BlobConfig:
    """Colour signature of the base: BGR colour `colour`; a pixel is a candidate when its
    signature score (projection of (pixel - background grey) on the colour direction minus the
    orthogonal residual) exceeds `min_score`. median_size: cv2.medianBlur kernel (odd).
    min_area [px]: smaller blobs are no detection. exclusion_dilate [px]: margin of the mask
    that keeps KLT features off the robot. refine_edges: fit the ellipse to the base's
    coverage map (`coverage_map` + `vision.ellipse.refine_ellipse`) and return points on it;
    False keeps the interpolated edge crossings (the seed's edge points). edge_band [px]: half
    width of the band of pixels the edge fit uses. sectors: angular sectors of the background
    ring, each with its own background colour in the coverage map."""

    colour: tuple[float, float, float] = (40.0, 40.0, 200.0)
    min_score: float = setting(50.0, gt=0.0)
    median_size: int = setting(3, ge=1)
    min_area: float = setting(20.0, gt=0.0)
    exclusion_dilate: int = setting(6, ge=0)
    refine_edges: bool = True
    edge_band: float = setting(4.0, ge=1.5)
    sectors: int = setting(16, ge=1)

    def __post_init__(self):
        if self.median_size % 2 != 1:
            raise ValueError(f"BlobConfig.median_size must be odd, got {self.median_size!r}")


def colour_score(image: np.ndarray, config: BlobConfig = BlobConfig()) -> np.ndarray:
    """(H,W) float32 colour-signature score of a BGR image: chroma of each pixel (pixel minus its
    own grey level) projected on the chroma of `config.colour`, minus the off-direction part."""
    image = check_image(image, "colour_score: image (BGR)", channels=(3,))
    px = image.astype(np.float32)
    chroma = px - px.mean(axis=2, keepdims=True)
    ref = np.asarray(config.colour, np.float32)
    ref = ref - ref.mean()
    ref /= max(float(np.linalg.norm(ref)), 1e-6)
    along = chroma @ ref
    off = np.linalg.norm(chroma - along[..., None] * ref, axis=2)
    return along - off


@dataclass(frozen=True)
class BlobRim:
    """rim (M,2) sub-pixel rim points of the largest blob (on the refined ellipse, or the edge
    crossings when refinement is off); crossings (K,2): the interpolated edge crossings; mask
    (H,W) uint8 of the blob (after the median filter); exclusion (H,W) uint8 dilated blob (no
    KLT features there); area [px]; refinement: the edge fit (None when off or failed);
    refine_error: why the edge fit failed ('' otherwise; rim then holds the crossings and the
    caller decides whether to use them)."""

    rim: np.ndarray
    crossings: np.ndarray
    mask: np.ndarray
    exclusion: np.ndarray
    area: float
    refinement: EllipseRefinement | None = None
    refine_error: str = ""


def coverage_map(
    image: np.ndarray, mask: np.ndarray, sectors: int = 16, pad: int = 7
) -> tuple[np.ndarray, tuple[int, int]]:
    """Fraction of each pixel covered by the base (alpha matting with two colours): every pixel
    near the blob is modelled as p = alpha B + g tau, B the base colour (median of the blob's
    interior), tau the background's colour direction (mean colour of a ring 3-6 px outside
    the blob, per angular sector, interpolated in angle) and g its unknown brightness, solved
    per pixel by linear least squares. The background's texture changes its brightness, not
    its hue, so unlike a threshold on a colour score the edge does not move with the texture
    behind it. Returns alpha (h,w) over the blob's box padded by `pad` px and that box's
    top-left pixel (x0, y0). ValueError when the base and background colours are parallel, or
    image is not a non-empty uint8 BGR image with a mask of its size."""
    px = check_image(image, "coverage_map: image (BGR)", channels=(3,)).astype(np.float64)
    mask = np.asarray(mask)
    if mask.shape != px.shape[:2]:
        raise ValueError(f"coverage_map: mask shape {mask.shape} != image shape {px.shape[:2]}")
    mask = mask > 0
    if isinstance(sectors, bool) or not isinstance(sectors, (int, np.integer)) or sectors < 1:
        raise ValueError(f"coverage_map: sectors must be an integer >= 1, got {sectors!r}")
    ys, xs = np.nonzero(mask)
    if ys.size == 0:
        raise ValueError("coverage_map: empty blob mask")
    m8 = mask.astype(np.uint8)
    inner = cv2.erode(m8, np.ones((5, 5), np.uint8)) > 0
    base = np.median(px[inner if inner.any() else mask], axis=0)
    ring = (cv2.dilate(m8, np.ones((13, 13), np.uint8)) > 0) & ~(
        cv2.dilate(m8, np.ones((7, 7), np.uint8)) > 0
    )
    if not ring.any():
        raise ValueError("coverage_map: no background pixels around the blob")
    x0, y0 = max(int(xs.min()) - pad, 0), max(int(ys.min()) - pad, 0)
    x1, y1 = (
        min(int(xs.max()) + pad + 1, mask.shape[1]),
        min(int(ys.max()) + pad + 1, mask.shape[0]),
    )
    box = px[y0:y1, x0:x1]
    cy, cx = ys.mean(), xs.mean()
    ry, rx = np.nonzero(ring)
    ring_px = px[ry, rx]
    sector_of = ((np.arctan2(ry - cy, rx - cx) + np.pi) / (2 * np.pi) * sectors).astype(
        int
    ) % sectors
    counts = np.bincount(sector_of, minlength=sectors)
    sums = np.stack(
        [np.bincount(sector_of, ring_px[:, i], minlength=sectors) for i in range(3)], axis=1
    )
    taus = np.where(
        counts[:, None] > 0, sums / np.maximum(counts, 1)[:, None], ring_px.mean(axis=0)
    )
    taus /= np.maximum(np.linalg.norm(taus, axis=1, keepdims=True), 1e-9)
    gy, gx = np.mgrid[y0:y1, x0:x1]
    f = (np.arctan2(gy - cy, gx - cx) + np.pi) / (2 * np.pi) * sectors - 0.5
    i0 = np.floor(f).astype(int) % sectors
    w = (f - np.floor(f))[..., None]
    tau = (1.0 - w) * taus[i0] + w * taus[(i0 + 1) % sectors]
    bb = base @ base
    bt = tau @ base
    tt = np.einsum("ijk,ijk->ij", tau, tau)
    det = bb * tt - bt * bt
    if not np.all(det > 1e-3 * bb * tt):
        raise ValueError(
            f"coverage_map: the base colour {np.round(base, 1)} is parallel to the background's "
            f"(cannot separate them)"
        )
    alpha = (tt * (box @ base) - bt * np.einsum("ijk,ijk->ij", box, tau)) / det
    return alpha, (x0, y0)


def detect_base_rim(image: np.ndarray, config: BlobConfig = BlobConfig()) -> BlobRim | None:
    """Largest blob of the base colour -> its sub-pixel rim, or None when no blob of `min_area`
    px exists: the crossings of the level half-way between the blob's interior and surroundings on
    every horizontal and vertical pixel pair (not biased inwards as the mask's integer contour is);
    with config.refine_edges, 90 points on the ellipse `refine_ellipse` fits to the blob's
    `coverage_map`. A failed refinement is reported in BlobRim.refine_error, never raised."""
    score = colour_score(image, config)
    h, w = score.shape
    with opencv_errors(f"detect_base_rim on a {w}x{h} image"):
        return _base_rim(image, score, config)


def _base_rim(image: np.ndarray, score: np.ndarray, config: BlobConfig) -> BlobRim | None:
    mask = (score > config.min_score).astype(np.uint8) * 255
    if config.median_size > 1:
        mask = cv2.medianBlur(mask, config.median_size)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return None
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    area = float(stats[best, cv2.CC_STAT_AREA])
    if area < config.min_area:
        return None
    blob = (labels == best).astype(np.uint8) * 255
    ring = cv2.dilate(blob, np.ones((5, 5), np.uint8)) & ~cv2.dilate(
        blob, np.ones((3, 3), np.uint8)
    )
    inner = cv2.erode(blob, np.ones((3, 3), np.uint8))
    inside_level = (
        float(np.median(score[inner > 0])) if (inner > 0).any() else float(score[blob > 0].max())
    )
    outside_level = float(np.median(score[ring > 0])) if (ring > 0).any() else 0.0
    level = 0.5 * (inside_level + outside_level)
    x, y, bw, bh = (int(v) for v in stats[best, :4])
    x0, y0 = max(x - 3, 0), max(y - 3, 0)
    x1, y1 = min(x + bw + 3, score.shape[1]), min(y + bh + 3, score.shape[0])
    region = cv2.dilate(blob, np.ones((5, 5), np.uint8))[y0:y1, x0:x1] > 0
    above = score[y0:y1, x0:x1] - level
    points = []
    for axis in (1, 0):  # crossings between horizontal, then vertical, pixel neighbours
        a = above[:, :-1] if axis == 1 else above[:-1, :]
        b = above[:, 1:] if axis == 1 else above[1:, :]
        both = region[:, :-1] & region[:, 1:] if axis == 1 else region[:-1, :] & region[1:, :]
        rows, cols = np.nonzero(both & ((a > 0) != (b > 0)))
        frac = a[rows, cols] / (a[rows, cols] - b[rows, cols])
        u = cols + (frac if axis == 1 else 0.0)
        v = rows + (frac if axis == 0 else 0.0)
        points.append(np.column_stack([u + x0, v + y0]))
    rim = np.vstack(points)
    exclusion = (
        cv2.dilate(blob, np.ones((2 * config.exclusion_dilate + 1,) * 2, np.uint8))
        if config.exclusion_dilate
        else blob
    )
    rim = rim.astype(float)
    if not config.refine_edges:
        return BlobRim(rim, rim, blob, exclusion, area)
    try:
        if len(rim) < 6:
            raise ValueError(f"{len(rim)} edge crossings, too few to start the ellipse fit")
        alpha, origin = coverage_map(image, blob, config.sectors)
        refinement = refine_ellipse(alpha, origin, fit_ellipse(rim), band=config.edge_band)
    except ValueError as exc:
        return BlobRim(rim, rim, blob, exclusion, area, None, f"edge refinement failed: {exc}")
    return BlobRim(ellipse_points(refinement.ellipse), rim, blob, exclusion, area, refinement)
