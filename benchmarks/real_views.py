"""Ground + ceiling view pairs cut from one real indoor scan (issue 16's protocol).

A gravity-aligned real fragment (z up, origin at its sensor; `tests/data/real_room`) is split
along a horizontal axis into two views that share a chosen fraction of their points: with
each view holding the fraction f = 1 / (2 - o) of the fragment (by quantiles of the split
axis), the shared slab holds 2f - 1 of it, which is the fraction o of either view. Each view
is then subsampled independently (Bernoulli, `keep`) and gets isotropic Gaussian noise
(`noise_m`). The first view is the ground robot's scan, in the fragment's frame G. The
second is a ceiling robot's scan: its sensor `height` metres above G's origin, upside down
(x kept, y and z flipped) and turned by a uniform random yaw, above the centroid of its view;
its points are expressed in that frame C. `perturb` makes a pose hint at an exact angular
and translational distance from the truth, in a random direction (right perturbation).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.mapping.io import read_points

FRAGMENT = (
    Path(__file__).resolve().parents[1] / "tests" / "data" / "real_room" / "tum_fr3_office.ply"
)
BUNDLED_FRAGMENTS = (FRAGMENT, FRAGMENT.parent / "redwood_livingroom.ply")  # README there


@dataclass(frozen=True)
class ViewPair:
    """ground (N,3) in G; ceiling (M,3) in C; T_ground_ceiling (4,4) the truth; overlap: the
    fraction of the ground view's points inside the shared slab (after subsampling)."""

    ground: np.ndarray
    ceiling: np.ndarray
    T_ground_ceiling: np.ndarray
    overlap: float


def load_fragment(path=None) -> np.ndarray:
    """(N,3) points of the real fragment (default: the repository's TUM office fragment)."""
    path = Path(path) if path is not None else FRAGMENT
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: real fragment missing (see tests/data/real_room/README.md)"
        )
    return read_points(path)


def ceiling_pose(yaw: float, position: np.ndarray) -> np.ndarray:
    """T_G_C of an upside-down sensor: R = Rz(yaw) diag(1, -1, -1), translation `position`."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", yaw).as_matrix() @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = position
    return T


def make_view_pair(
    points: np.ndarray,
    overlap: float,
    rng: np.random.Generator,
    keep: float = 0.5,
    noise_m: float = 0.005,
    height: float = 2.5,
    axis: int = 1,
) -> ViewPair:
    """Split gravity-aligned (N,3) `points` into a ground and a ceiling view (module docstring)."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 100:
        raise ValueError(f"make_view_pair: need (N,3) points with N >= 100, got {pts.shape}")
    if not 0.0 < overlap < 1.0 or not 0.0 < keep <= 1.0:
        raise ValueError(
            f"make_view_pair: overlap in (0, 1) and keep in (0, 1], got {overlap}, {keep}"
        )
    f = 1.0 / (2.0 - overlap)
    lo, hi = np.quantile(pts[:, axis], [f, 1.0 - f])  # ground: s <= lo; ceiling: s >= hi; hi <= lo
    views = []
    for sel in (pts[:, axis] <= lo, pts[:, axis] >= hi):
        v = pts[sel][rng.random(int(sel.sum())) < keep]
        views.append(v + rng.normal(0.0, noise_m, v.shape))
    ground, ceiling_g = views
    shared = float(np.mean(ground[:, axis] >= hi))
    centre = ceiling_g.mean(axis=0)
    T = ceiling_pose(rng.uniform(-np.pi, np.pi), np.array([centre[0], centre[1], height]))
    ceiling = (ceiling_g - T[:3, 3]) @ T[:3, :3]  # R^T (p - t), row-wise
    return ViewPair(ground, ceiling, T, shared)


def perturb(T: np.ndarray, rot_deg: float, trans_m: float, rng: np.random.Generator) -> np.ndarray:
    """T Exp(xi) with |rotation| = rot_deg about a random axis and |translation| = trans_m in a
    random direction (in G)."""
    axis, direction = rng.normal(size=3), rng.normal(size=3)
    out = np.array(T, dtype=float)
    out[:3, :3] = (
        T[:3, :3]
        @ Rotation.from_rotvec(np.deg2rad(rot_deg) * axis / np.linalg.norm(axis)).as_matrix()
    )
    out[:3, 3] = T[:3, 3] + trans_m * direction / np.linalg.norm(direction)
    return out
