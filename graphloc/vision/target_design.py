"""Design of marker targets, seed 001 (001_0f8f8dae37ce6b79.txt) section III-A "Optimization
of target geometries": cost (1), f = w s_min + (1-w) s_avg when D1 <= d <= D2 and
h_min >= H, else -G; maximized with Nelder-Mead from random starts."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize
from tqdm import tqdm

from graphloc.config_schema import config_dataclass, setting


@config_dataclass
class TargetDesignConfig:
    """Seed 001 III-A eq. (1): n targets x m markers, lengths in metres.
    weight w, distance bounds D1 <= d <= D2, minimum face height H, penalty G. `tolerance`
    relaxes the bounds (the published vertices are rounded to 0.1 mm: one distance is 30.01 cm
    for D2 = 30 cm). h_min is the smallest distance of a marker from the plane of any three
    others of its target (flat and collinear arrangements both make it small)."""

    n_targets: int = setting(1, ge=1)
    n_markers: int = setting(4, ge=4)
    weight: float = setting(2.0 / 3.0, ge=0.0, le=1.0)
    d_min: float = setting(0.15, gt=0.0)
    d_max: float = 0.30
    min_height: float = setting(0.12, ge=0.0)
    penalty: float = setting(1.0, ge=0.0)
    tolerance: float = setting(5e-4, ge=0.0)
    n_starts: int = setting(20, ge=1)
    n_samples: int = setting(20000, ge=1)  # random configurations screened for feasible starts
    maxiter: int = setting(1500, ge=1)
    restarts: int = 1  # Nelder-Mead runs per start, each from the previous optimum
    seed: int = 0

    def __post_init__(self):
        if not 0.0 < self.d_min < self.d_max:
            raise ValueError(
                f"TargetDesignConfig.d_min must be in (0, d_max = {self.d_max:g}), got {self.d_min}"
            )


def _index_sets(m: int):
    pairs = np.array(list(itertools.combinations(range(m), 2)))
    quads = np.array(list(itertools.combinations(range(m), 4)))
    # every (apex, face) split of every quadruple
    apex = np.concatenate([quads[:, [k]] for k in range(4)])
    face = np.concatenate([np.delete(quads, k, axis=1) for k in range(4)])
    return pairs, apex[:, 0], face


def design_cost(
    points: np.ndarray, config: TargetDesignConfig = TargetDesignConfig()
) -> np.ndarray:
    """Seed 001 eq. (1) for a batch of systems: points (..., n, m, 3) [m] -> f (...,).

    d: all pairwise marker distances inside each target, pooled over the n targets; S = |d_i - d_j|
    over all pairs of them; f = w min(S) + (1-w) mean(S) if all d in [D1, D2] and h_min >= H,
    else -G."""
    P = np.asarray(points, dtype=float)
    if P.shape[-3:] != (config.n_targets, config.n_markers, 3):
        raise ValueError(
            f"design_cost: points must be (..., {config.n_targets}, {config.n_markers}, 3), "
            f"got {P.shape}"
        )
    pairs, apex, face = _index_sets(config.n_markers)
    d = np.linalg.norm(P[..., pairs[:, 0], :] - P[..., pairs[:, 1], :], axis=-1)  # (..., n, pairs)
    A, B, C = (P[..., face[:, k], :] for k in range(3))
    normal = np.cross(B - A, C - A)
    area2 = np.linalg.norm(normal, axis=-1)
    h = np.abs(np.einsum("...k,...k->...", P[..., apex, :] - A, normal)) / np.maximum(area2, 1e-300)
    h_min = h.min(axis=(-1, -2))
    dd = d.reshape(*d.shape[:-2], -1)
    iu, ju = np.triu_indices(dd.shape[-1], 1)
    S = np.abs(dd[..., iu] - dd[..., ju])
    f = config.weight * S.min(axis=-1) + (1 - config.weight) * S.mean(axis=-1)
    tol = config.tolerance
    feasible = (
        (dd.min(axis=-1) >= config.d_min - tol)
        & (dd.max(axis=-1) <= config.d_max + tol)
        & (h_min >= config.min_height - tol)
    )
    return np.where(feasible, f, -config.penalty)


@dataclass(frozen=True)
class TargetDesign:
    """Best design `points` (n,m,3) [m] with cost `cost`; `start_costs` / `final_costs` per
    start."""

    points: np.ndarray
    cost: float
    start_costs: np.ndarray
    final_costs: np.ndarray
    n_feasible_samples: int = 0
    meta: dict = field(default_factory=dict, compare=False)


def design_targets(
    config: TargetDesignConfig = TargetDesignConfig(), progress: bool = False
) -> TargetDesign:
    """Maximize eq. (1) with scipy Nelder-Mead from `n_starts` random feasible starts (seed III-A).

    Starts: `n_samples` random configurations (markers uniform in a cube of side D2), screened
    in one vectorized cost evaluation; `n_starts` of the feasible ones, drawn at random, seed
    Nelder-Mead. The result
    is centred on its centroid per target."""
    rng = np.random.default_rng(config.seed)
    shape = (config.n_targets, config.n_markers, 3)
    samples = rng.uniform(0.0, config.d_max, size=(config.n_samples, *shape))
    costs = design_cost(samples, config)
    feasible = np.flatnonzero(costs > -config.penalty)
    if len(feasible) == 0:
        raise ValueError(
            f"design_targets: no feasible start among {config.n_samples} samples; "
            f"relax d_min/d_max/min_height or raise n_samples"
        )
    rng.shuffle(feasible)
    starts = feasible[: config.n_starts]
    best_x, best_f, finals = None, -np.inf, []
    iterator = starts
    if progress:
        iterator = tqdm(starts, desc="target design (Nelder-Mead)")
    for s in iterator:
        x = samples[s].ravel()
        for _ in range(config.restarts):  # a fresh simplex around the last optimum escapes stalls
            res = minimize(
                lambda x: -float(design_cost(x.reshape(shape), config)),
                x,
                method="Nelder-Mead",
                options={"maxiter": config.maxiter, "xatol": 1e-6, "fatol": 1e-9},
            )
            x = res.x
        f = -float(res.fun)
        finals.append(f)
        if f > best_f:
            best_f, best_x = f, res.x.reshape(shape)
    best_x = best_x - best_x.mean(axis=1, keepdims=True)
    return TargetDesign(
        points=best_x,
        cost=best_f,
        start_costs=costs[starts],
        final_costs=np.array(finals),
        n_feasible_samples=len(feasible),
    )
