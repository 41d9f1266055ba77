"""Recovery steps of the seed-001 marker blob extraction (seeds/001_0f8f8dae37ce6b79.txt,
section IV-B): too many blobs -> merge the closest pair or remove the blob farthest from the
others (`reduce_blobs`); too few -> circular Hough transform (`hough_blobs`; the erosion step
is in `graphloc.vision.markers`)."""

from __future__ import annotations

import cv2
import numpy as np

from graphloc.vision.blobs import Blobs, reject, stats_from_labels
from graphloc.vision.marker_config import MarkerDetectorConfig


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
