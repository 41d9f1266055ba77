"""Seed 001 (001_0f8f8dae37ce6b79.txt) target pieces graphloc's front-end does not use, for the
seed's reproduction and tests: the design of marker targets (section III-A "Optimization of
target geometries": cost (1), f = w s_min + (1-w) s_avg when D1 <= d <= D2 and h_min >= H,
else -G; maximized with Nelder-Mead from random starts), the pose prediction (IV-A), the
prediction's search window and blob-size bounds (IV-B), and the hypotheses of one frame (IV-C,
graphloc.vision.target.target_hypotheses_frames)."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Sequence

import gtsam
import numpy as np
from scipy.optimize import minimize
from tqdm import tqdm

from graphloc.candidates import CandidateSet
from graphloc.config_schema import config_dataclass, setting
from graphloc.vision.target import (
    LARGE_TARGET,
    MarkerTarget,
    TargetHypothesisConfig,
    as_pose3,
    target_hypotheses_frames,
)


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


def predict_pose(
    history: Sequence,
    k_R: int = 2,
    times: Sequence[float] | None = None,
    t_next: float | None = None,
) -> gtsam.Pose3:
    """Seed 001 IV-A: linear regression over the last `k_R` poses, extrapolated one step.

    history: gtsam.Pose3 or (R, t) of the camera in the target frame, oldest first. times:
    their timestamps (default 0, 1, 2, ...) and t_next the time to predict (default last + 1).
    The regression xi(tau) = a + b tau is fitted to xi_i = Logmap(T_last^-1 T_i); prediction
    T_last Expmap(a + b t_next). k_R = 2 is constant velocity on SE(3).
    """
    if k_R < 1:
        raise ValueError(f"predict_pose: k_R must be >= 1, got {k_R}")
    poses = [as_pose3(p) for p in history][-k_R:]
    if not poses:
        raise ValueError("predict_pose: empty pose history")
    n_all = len(history)
    tau = np.arange(n_all, dtype=float) if times is None else np.asarray(times, dtype=float)
    if tau.shape != (n_all,) or not np.isfinite(tau).all():
        raise ValueError(
            f"predict_pose: times must be {n_all} finite values, got shape {tau.shape}"
        )
    tau = tau[-k_R:]
    if np.any(np.diff(tau) <= 0):
        raise ValueError(f"predict_pose: times must increase, got {tau.tolist()}")
    t_next = (
        tau[-1] + (tau[-1] - tau[-2] if len(tau) > 1 else 1.0) if t_next is None else float(t_next)
    )
    last = poses[-1]
    if len(poses) == 1:
        return last
    xi = np.array([gtsam.Pose3.Logmap(last.between(p)) for p in poses])  # (k,6), last row 0
    A = np.column_stack([np.ones(len(tau)), tau - tau[-1]])
    coef, *_ = np.linalg.lstsq(A, xi, rcond=None)
    return last.compose(gtsam.Pose3.Expmap(coef[0] + coef[1] * (t_next - tau[-1])))


def target_hypotheses(
    detections: np.ndarray,
    camera,
    target: MarkerTarget = LARGE_TARGET,
    config: TargetHypothesisConfig = TargetHypothesisConfig(),
    predicted=None,
    time: float = 0.0,
    observer: str = "",
    observed: str = "",
) -> CandidateSet:
    """All plausible camera poses in the target frame from 4 (or 3) blobs of identical markers.

    detections: (4,2) pixels in any order. predicted: predicted camera pose (gtsam.Pose3 or (R,t))
    restricting the assignments (seed IV-C); if no assignment is compatible, all are tried.
    With 4 detections, hypotheses whose fourth marker misses its detection by more than
    `gate_px` are dropped. With 3 (one marker lost, seed V-A) nothing can be gated: every P3P
    solution is returned and a prediction is the only restriction. If no 4-blob hypothesis
    passes the gate (one blob is not a marker, e.g. a partly occluded one), every 3-of-4 subset
    is tried the same way (meta["fallback"] = "three_of_four"). meta: assignment (K,4) =
    detection index of each marker (-1 unseen), reprojection_px (K,) rms, gate_error_px (K,),
    n_assignments, prediction_used, fallback. One frame of `target_hypotheses_frames`.
    """
    return target_hypotheses_frames(
        [detections], camera, target, config, [predicted], [time], observer, observed
    )[0]


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
