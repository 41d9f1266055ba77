"""Blob moments and outlier rejection of the seed-001 marker blob extraction
(seeds/001_0f8f8dae37ce6b79.txt, section IV-B): connected components -> additive raw moments
(merging two blobs is a row sum) -> first / second outlier rejection (size, eccentricity,
non-convexity) and the window-cut rule. Used by `graphloc.vision.markers`."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from graphloc.vision.marker_config import MarkerDetectorConfig


@dataclass
class Blobs:
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
    def empty() -> "Blobs":
        return Blobs(
            np.zeros(0),
            np.zeros((0, 5)),
            np.zeros((0, 3)),
            np.zeros((0, 4), int),
            np.zeros(0),
            np.zeros(0, bool),
        )

    def take(self, idx) -> "Blobs":
        return Blobs(
            self.n[idx],
            self.s[idx],
            self.w[idx],
            self.box[idx],
            self.solidity[idx],
            self.hough[idx],
        )

    def concat(self, other: "Blobs") -> "Blobs":
        return Blobs(
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

    def merge(self, i: int, j: int) -> "Blobs":
        keep = [k for k in range(len(self)) if k not in (i, j)]
        box = np.concatenate(
            [
                np.minimum(self.box[i, :2], self.box[j, :2]),
                np.maximum(self.box[i, 2:], self.box[j, 2:]),
            ]
        )
        merged = Blobs(
            np.array([self.n[i] + self.n[j]]),
            (self.s[i] + self.s[j])[None],
            (self.w[i] + self.w[j])[None],
            box[None],
            np.array([min(self.solidity[i], self.solidity[j])]),
            np.array([self.hough[i] or self.hough[j]]),
        )
        return self.take(keep).concat(merged)


def label_stats(
    mask: np.ndarray, weight: np.ndarray, origin: tuple[int, int]
) -> tuple[Blobs, np.ndarray]:
    """Connected components of `mask` (a window at `origin`=(x0,y0)) -> moments of every blob
    (vectorized)."""
    n_lab, labels, stats, _ = cv2.connectedComponentsWithStats(
        mask.astype(np.uint8), connectivity=8
    )
    return stats_from_labels(labels, n_lab, stats[:, :4], weight, origin), labels


def stats_from_labels(labels, n_lab, bbox_xywh, weight, origin) -> Blobs:
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
    return Blobs(cnt, s.reshape(B, 5), ws.reshape(B, 3), box, np.ones(B), np.zeros(B, bool))


def blob_solidity(labels: np.ndarray, label: int, box_local: np.ndarray) -> float:
    """Contour area / convex-hull area of one labelled blob (1 for blobs too small to tell)."""
    x0, y0, x1, y1 = box_local
    crop = (labels[y0:y1, x0:x1] == label).astype(np.uint8)
    contours, _ = cv2.findContours(crop, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    contour = max(contours, key=len)
    hull_area = cv2.contourArea(cv2.convexHull(contour))
    if hull_area < 4.0:
        return 1.0
    return float(cv2.contourArea(contour) / hull_area)


def reject(
    blobs: Blobs,
    labels: np.ndarray,
    origin,
    config: MarkerDetectorConfig,
    counts: dict,
    exclude: np.ndarray | None = None,
) -> Blobs:
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
        [blob_solidity(labels, i + 1, blobs.box[i] - [x0, y0, x0, y0]) for i in idx], dtype=float
    )
    blobs.solidity[idx] = sol
    convex = sol >= config.min_solidity
    counts["non_convex"] = counts.get("non_convex", 0) + int((~convex).sum())
    return blobs.take(idx[convex])


def window_cut(box: np.ndarray, window, width: int, height: int, counts: dict) -> np.ndarray:
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
