"""What a robust inter-robot registration must pass before it is fused (issue 16): the
per-candidate checks (`candidate_checks`), the point-to-plane residuals and costs they are
computed from at the scans' own residual scale, and the `RegistrationDecision` that
`robust_register` returns (every candidate, every check, why each candidate lost)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graphloc.mapping.config import AcceptanceConfig
from graphloc.mapping.registration import PreparedCloud, Registration
from graphloc.mapping.registration_covariance import block_labels
from graphloc.mapping.registration_index import NearestIndex


# why a failed check refuses a fusion, per check of `candidate_checks` and `robust_register`
CHECK_REASONS = {
    "overlap": "too little overlap",
    "inlier_ratio": "residuals inconsistent with a fit",
    "contradicted_fraction": "surfaces both robots saw do not meet (a slid or turned view)",
    "conditioning": "degenerate geometry (a direction is unconstrained)",
    "hint_mahalanobis2": "disagrees with the pose hint beyond its covariance",
    "ceiling_height_m": "ceiling robot below the ground robot",
    "ceiling_z_down_cos": "ceiling robot not upside down",
    "cost_margin_se": "another registration fits about as well (ambiguous)",
    "overlap_shortfall": "another registration explains far more of the views (a retreat)",
    "polish_rounds": "the pose kept moving under the last refinement (a view sliding along)",
    "sigma_rot_deg": "too uncertain (rotation)",
    "sigma_trans_m": "too uncertain (translation)",
}


@dataclass(frozen=True)
class Candidate:
    """One start of the multi-start registration after coarse + fine ICP: T_target_source,
    truncated point-to-plane cost per source point (the mean of `truncated_costs`), overlap (inlier
    fraction), inlier ratio among near points, Mahalanobis^2 to the hint, and the fraction of
    near points in contradicting cubes (`contradicted_fraction`)."""

    start: int
    transformation: np.ndarray
    cost: float
    overlap: float
    inlier_ratio: float
    hint_d2: float
    contradicted: float

    def as_dict(self) -> dict:
        return {
            "start": self.start,
            "cost": self.cost,
            "overlap": self.overlap,
            "inlier_ratio": self.inlier_ratio,
            "hint_mahalanobis2": self.hint_d2,
            "contradicted_fraction": self.contradicted,
            "translation_m": self.transformation[:3, 3].tolist(),
        }


@dataclass(frozen=True)
class RegistrationDecision:
    """Outcome of `robust_register`: the chosen candidate (`registration`, its
    information from the residual-scaled point-to-plane Hessian), whether every check passed,
    the failed checks' reasons, every check's (value, threshold, passed), all candidates with
    why each lost, wall time [s], and `timings`: seconds per stage of `robust_register`
    (coarse: clouds, pyramid and coarse ICP of every start; fine: the fine stages; checks: the
    candidates' residuals; global: the FPFH fallback; polish; rest: final checks, covariance)
    with the number of starts, of fine stages, of polish rounds, of weak-direction probes and of
    rivals polished, `residual_scale`: the checks' c [m] (`residual_scale`), and
    `covariance_terms`: the uncalibrated (P, Q) that `covariance` calibrates
    (`graphloc.mapping.registration_covariance.calibrated_covariance`; None when not computed)."""

    registration: Registration
    accepted: bool
    reasons: tuple
    checks: dict
    candidates: tuple
    best: int
    lost: dict
    covariance: np.ndarray
    seconds: float
    timings: dict | None = None
    residual_scale: float | None = None
    covariance_terms: tuple | None = None

    def as_dict(self) -> dict:
        return {
            "accepted": bool(self.accepted),
            "reasons": list(self.reasons),
            "checks": {
                k: {"value": float(v[0]), "threshold": float(v[1]), "passed": bool(v[2])}
                for k, v in self.checks.items()
            },
            "best_candidate": self.best,
            "candidates": [dict(c.as_dict(), lost=self.lost.get(c.start)) for c in self.candidates],
            "merged_starts": {
                k: v for k, v in self.lost.items() if k not in {c.start for c in self.candidates}
            },
            "sigma_rot_deg": np.degrees(np.sqrt(np.diag(self.covariance)[:3])).tolist(),
            "sigma_trans_m": np.sqrt(np.diag(self.covariance)[3:]).tolist(),
            "seconds": self.seconds,
            "timings": self.timings,
            "residual_scale_m": self.residual_scale,
        }


def candidate_checks(o: Candidate, acc: AcceptanceConfig) -> dict:
    """name -> (value, threshold, passed) of the checks one candidate can fail on its own."""
    checks = {
        "overlap": (o.overlap, acc.min_overlap, o.overlap >= acc.min_overlap),
        "inlier_ratio": (
            o.inlier_ratio,
            acc.min_inlier_ratio,
            o.inlier_ratio >= acc.min_inlier_ratio,
        ),
        "contradicted_fraction": (
            o.contradicted,
            acc.max_contradicted,
            o.contradicted <= acc.max_contradicted,
        ),
        "hint_mahalanobis2": (o.hint_d2, acc.hint_gate, o.hint_d2 <= acc.hint_gate),
    }
    if acc.ceiling_above:
        T = o.transformation
        height, down = float(T[2, 3]), float(-T[2, 2])
        min_down = float(np.cos(np.deg2rad(acc.max_ceiling_tilt_deg)))
        checks["ceiling_height_m"] = (height, 0.0, height > 0.0)
        checks["ceiling_z_down_cos"] = (down, min_down, down >= min_down)
    return checks


def overlap_shortfall(winner_overlap: float, candidates, acc: AcceptanceConfig) -> tuple:
    """(value, threshold, passed) of the winner's overlap shortfall (AcceptanceConfig
    .max_overlap_shortfall): the largest overlap among the `candidates` that pass the hint gate
    and the robot geometry, over `winner_overlap` (a candidate at about the winner's pose,
    the winner's own, overlaps about as much: only a distinct pose can overlap far more); 0 when
    none passes them."""
    gates = ("hint_mahalanobis2", "ceiling_height_m", "ceiling_z_down_cos")
    rivals = [
        o.overlap
        for o in candidates
        if all(v[2] for k, v in candidate_checks(o, acc).items() if k in gates)
    ]
    value = max(rivals, default=0.0) / max(winner_overlap, 1e-12)
    return value, acc.max_overlap_shortfall, value <= acc.max_overlap_shortfall


def point_to_plane(source: PreparedCloud, target: PreparedCloud, T: np.ndarray, nns):
    """Per source point (transformed by T): point-to-plane residual to its nearest target point
    along that point's normal, the distance to it, and the Jacobian rows [(p x n)^T, n^T] of the
    residual for a left perturbation Exp(xi) T (rot, trans). Nearest neighbours within the
    radius of `nns` (`target_index`); a point without one has distance inf, residual and
    Jacobian row 0."""
    p = source.points @ T[:3, :3].T + T[:3, 3]
    idx, d = nns.nearest(p)
    has = idx >= 0
    n = np.zeros_like(p)
    n[has] = target.cloud.point.normals.numpy().astype(float)[idx[has]]
    r = np.einsum("ij,ij->i", p - target.points[np.where(has, idx, 0)], n)
    J = np.hstack([np.cross(p, n), n])
    return r, d, J


def target_index(target: PreparedCloud, radius: float) -> NearestIndex:
    """Nearest-neighbour index of the target's points within `radius` (for `point_to_plane`;
    every check counts only correspondences within the fine distance)."""
    return NearestIndex(target.points, radius)


def truncated_costs(
    r: np.ndarray, d: np.ndarray, c: float, max_dist: float, misfit: float
) -> np.ndarray:
    """Truncated least squares per source point (a candidate's cost is their mean): r^2 / c^2
    for a point on a target surface (|r| < c), `misfit` for a point with a target point within
    max_dist but off its surface, 1 for a point with no target point within max_dist (an
    unexplained point)."""
    near = d < max_dist
    on = near & (np.abs(r) < c)
    return np.where(on, r * r / (c * c), np.where(near, misfit, 1.0))


def cost_margin_se(winner: np.ndarray, rival: np.ndarray, label: np.ndarray) -> float:
    """How far a rival registration's cost lies above the winner's, in standard errors: the
    paired difference d_i = rival_i - winner_i of the per-point costs (`truncated_costs`, the
    same source points), its mean over the n points divided by its cluster-robust standard error
    sqrt(B / (B - 1) sum_b (S_b - n_b mean)^2) / n over the B source clusters `label` (S_b, n_b:
    cluster b's sum of d_i and its size; points of one surface err together, Liang & Zeger
    1986). Without spread: inf when the rival costs more by the same in every cluster, 0 when
    it costs no more (as ambiguous as a tie)."""
    diff = np.asarray(rival, dtype=float) - np.asarray(winner, dtype=float)
    n, mean = len(diff), float(np.mean(diff))
    S, nb = np.bincount(label, weights=diff), np.bincount(label)
    B = len(nb)
    se = np.sqrt(B / max(B - 1, 1) * np.sum((S - nb * mean) ** 2)) / n
    if se > 0:
        return mean / se
    return float("inf") if mean > 0 else 0.0


def contradicted_fraction(points: np.ndarray, inlier: np.ndarray, acc: AcceptanceConfig) -> float:
    """Fraction of the near points (`points`, (n,3) in the target frame, `inlier`: |r| < c) that
    lie in cubes of side acc.contradiction_block holding at least acc.contradiction_min_points
    of them with an inlier ratio below acc.contradiction_ratio times the ratio over all of them:
    the parts of the overlap where the two views' surfaces are beside each other, not on each
    other (`AcceptanceConfig`). 0 without near points."""
    if len(points) == 0:
        return 0.0
    label = block_labels(points, acc.contradiction_block)
    n = np.bincount(label)
    k = np.bincount(label, weights=np.asarray(inlier, dtype=float))
    ratio = k.sum() / n.sum()
    bad = (n >= acc.contradiction_min_points) & (k < acc.contradiction_ratio * ratio * n)
    return float(n[bad].sum() / n.sum())


def only_slid_or_valid(o: Candidate, acc: AcceptanceConfig) -> bool:
    """True if a candidate passes every check of `candidate_checks` but, perhaps, the
    contradicted cubes (a slid view fails that one alone)."""
    return all(v[2] for k, v in candidate_checks(o, acc).items() if k != "contradicted_fraction")


def residual_scale(source: PreparedCloud, target: PreparedCloud, acc: AcceptanceConfig) -> float:
    """c [m], the residual scale of every check: the two scans' own residual spread
    sqrt((s_source^2 + s_target^2) / 2) (`PreparedCloud.residual_spread`, each scan's split
    halves), at least acc.residual_sigma (the thresholds' scale; a scan whose spread is not
    measured has that)."""
    spread = np.array([source.residual_spread, target.residual_spread], dtype=float)
    pair = float(np.sqrt(np.mean(spread**2))) if np.isfinite(spread).all() else 0.0
    return max(acc.residual_sigma, pair)
