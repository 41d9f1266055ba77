"""Nearest neighbours within a radius for the inter-robot registration of issue 16: the checks
of `graphloc.mapping.acceptance` (correspondences within the fine distance) and the overlap cut
of `graphloc.mapping.registration_stages.polish`."""

from __future__ import annotations

import numpy as np
import open3d as o3d


class NearestIndex:
    """Nearest neighbour of query points among `points` within a radius fixed at construction:
    Open3D's fixed-radius hybrid search (a hash grid of the radius), which answers a query
    without a neighbour in that radius at once (a k-d tree's k = 1 search walks on to the
    nearest point however far it is; every use here ignores points beyond a radius)."""

    def __init__(self, points: np.ndarray, radius: float):
        if not radius > 0:
            raise ValueError(f"NearestIndex: radius must be > 0, got {radius}")
        self.radius = float(radius)
        self._nns = o3d.core.nns.NearestNeighborSearch(
            o3d.core.Tensor(np.asarray(points, dtype=np.float64))
        )
        self._nns.hybrid_index(self.radius)

    def nearest(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(index, distance) of each query point's nearest point within the radius; -1 and inf
        where there is none."""
        idx, d2, _ = self._nns.hybrid_search(
            o3d.core.Tensor(np.asarray(query, dtype=np.float64)), self.radius, 1
        )
        idx = idx.numpy()[:, 0]
        d = np.sqrt(d2.numpy()[:, 0])
        d[idx < 0] = np.inf
        return idx, d
