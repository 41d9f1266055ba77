"""Perspective-three-point (P3P): every camera pose consistent with three bearings of three
known world points, batched over N instances in numpy (no Python loop per instance), by Lambda
Twist (Persson & Nordberg, ECCV 2018; `p3p_solvers`). The seeds' solvers (Grunert, seed 004
Sec. II-B; Finsterwalder, seed 000 Sec. III-B; Kneip, seed 001 Sec. III-C) plug into
`solve_p3p` from benchmarks/baselines/p3p_seeds.py.

Conventions: ``bearings`` (N,3,3), row i = direction to world point i in the camera frame
(normalized here); ``points`` (N,3,3), row i = world point i. Output: pose of the camera in the
world, X_i = R_wc @ (depth_i * f_i) + t_wc. Malformed shapes raise ValueError; degenerate
geometry (NaN/inf, zero or parallel bearings, coincident or collinear points) gives rows with
``valid`` all False and ``degenerate`` True. Every returned candidate has positive depths and
reprojects the three points within ``P3PConfig.max_residual_rad``. Vectors are tuples of three
arrays (`p3p_soa`); large batches run in blocks of BLOCK instances.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.candidates import CandidateSet
from graphloc.config_schema import config_dataclass, setting
from graphloc.geometry.p3p_soa import (
    cosines_and_sides,
    gather,
    soa,
    vcross,
    vdot,
    vnorm,
    vscale,
    vsub,
    vunit,
)
from graphloc.geometry.p3p_solvers import lambdatwist_depths, refine_depths

MAX_CANDIDATES = 4
BLOCK = 4096  # instances per vectorized pass (cache-sized)


@config_dataclass
class P3PConfig:
    """Thresholds of the solver (angles in radians, lengths relative to the longest side)."""

    # |f_i x f_j| below this -> parallel bearings, degenerate
    min_bearing_sine: float = setting(1e-6, ge=0.0)
    # |d12 x d13| / longest^2 below this -> collinear points
    min_triangle_ratio: float = setting(1e-6, ge=0.0)
    # reprojection check on every returned candidate
    max_residual_rad: float = setting(1e-6, gt=0.0)
    # candidate centres closer than this * longest side merge
    duplicate_tol: float = setting(1e-7, ge=0.0)
    # Gauss-Newton steps on the depths; None: the solver's own (lambdatwist 1)
    depth_refine_iters: int | None = setting(None, ge=0)
    polish_iters: int = setting(2, ge=0)  # Gauss-Newton steps on the pose when polish=True


@dataclass(frozen=True)
class P3PCandidates:
    """All candidates of N P3P instances; the valid ones come first in each row.

    R_wc (N,4,3,3), t_wc (N,4,3): camera pose in the world (zeros where invalid).
    valid (N,4) bool. residual (N,4): largest angle [rad] between a bearing and its reprojected
    point (inf where invalid). degenerate (N,) bool: input rejected before solving.
    """

    R_wc: np.ndarray
    t_wc: np.ndarray
    valid: np.ndarray
    residual: np.ndarray
    degenerate: np.ndarray
    method: str = "lambdatwist"

    def __len__(self) -> int:
        return self.valid.shape[0]

    def counts(self) -> np.ndarray:
        """(N,) number of valid candidates per instance."""
        return self.valid.sum(axis=1)

    def poses(self, i: int) -> list[gtsam.Pose3]:
        """Valid candidates of instance i as gtsam.Pose3 (camera in world)."""
        return self.candidate_set(i).poses()

    def candidate_set(self, i: int, bearing_sigma_rad: float = 1e-3, **context) -> CandidateSet:
        """Instance i as a CandidateSet, score = exp(-residual^2 / (2 sigma^2)). A minimal problem
        fits every genuine candidate exactly, so the scores are ~1 and do not choose among them.
        `context` is passed to CandidateSet (time, observer, observed, meta)."""
        keep = self.valid[i]
        scores = np.exp(-0.5 * (self.residual[i][keep] / bearing_sigma_rad) ** 2)
        return CandidateSet(
            R=self.R_wc[i][keep],
            t=self.t_wc[i][keep],
            scores=scores,
            source=f"p3p/{self.method}",
            **context,
        )


# ----------------------------------------------------------------------------- public API


def solve_p3p(
    bearings, points, polish: bool = False, config: P3PConfig = P3PConfig(), solver=None
) -> P3PCandidates:
    """All P3P candidates of N instances; bearings, points (N,3,3). See the module docstring.
    solver(F, P, config) -> flat candidates (R, t, instance, ok), `lambdatwist` when None; its
    __name__ is the candidates' method."""
    solver = lambdatwist if solver is None else solver
    f, X = _check_shapes(bearings, points)
    if f.shape[0] <= BLOCK:
        return _solve_block(f, X, solver, polish, config)
    # blocks that fit the CPU cache are ~2x faster than one pass over 100k instances
    parts = [
        _solve_block(f[s : s + BLOCK], X[s : s + BLOCK], solver, polish, config)
        for s in range(0, f.shape[0], BLOCK)
    ]
    return P3PCandidates(
        **{
            name: np.concatenate([getattr(p, name) for p in parts])
            for name in ("R_wc", "t_wc", "valid", "residual", "degenerate")
        },
        method=solver.__name__,
    )


def _solve_block(f, X, solver, polish, config) -> P3PCandidates:
    """solve_p3p on one block; numpy warnings are suppressed and bad values masked instead."""
    with np.errstate(all="ignore"):
        F, P, origin, degenerate, longest2 = _prepare(f, X, config)
        R, t, inst, ok_m = solver(F, P, config)
        F, P = gather(F, inst), gather(P, inst)
        if polish:
            R, t = _polish_pose(F, P, R, t, config.polish_iters)
        residual, in_front = _reprojection_check(F, P, R, t)
        ok_m &= in_front & (residual < config.max_residual_rad) & ~degenerate[inst]
        lim2 = config.duplicate_tol**2 * longest2[inst]
        return _assemble(R, t, residual, ok_m, inst, origin, degenerate, solver.__name__, lim2)


def depth_candidates(F, P, depths, iters):
    """Flat candidates (R, t, instance, ok) of a depth solver (cosines and sides -> up to four
    depth triples and a mask), its depths refined by `iters` Gauss-Newton steps."""
    geo = cosines_and_sides(F, P)
    FP = _triangle_frame(*P)  # world triangle frame, per instance
    lam, ok = depths(geo)
    # from here on only the candidates that exist: flat arrays of length M, sorted by instance
    inst, slot = np.nonzero(ok)
    lam = tuple(x[inst, slot] for x in lam)
    lam = refine_depths(tuple(x[inst, 0] for x in geo), lam, iters)
    ok_m = (lam[0] > 0) & (lam[1] > 0) & (lam[2] > 0)
    R, t = _pose_from_depths(gather(F, inst), gather(FP, inst), lam)
    return R, t, inst, ok_m


def lambdatwist(F, P, config):
    """The default solver of `solve_p3p`: Lambda Twist's depths, refined once."""
    iters = 1 if config.depth_refine_iters is None else config.depth_refine_iters
    return depth_candidates(F, P, lambdatwist_depths, iters)


# ----------------------------------------------------------------------------- input checks

# A well-conditioned stand-in for degenerate rows, so no NaN reaches the solvers (rows masked
# after).
_SAFE_X = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
_SAFE_F = (_SAFE_X - [0.2, 0.3, -3.0]) / np.linalg.norm(
    _SAFE_X - [0.2, 0.3, -3.0], axis=1, keepdims=True
)


def _check_shapes(bearings, points) -> tuple[np.ndarray, np.ndarray]:
    for name, arr in (("bearings", bearings), ("points", points)):
        if np.iscomplexobj(arr):
            raise ValueError(
                f"solve_p3p: {name} must be real numbers, got dtype {np.asarray(arr).dtype}"
            )
    try:
        f = np.asarray(bearings, dtype=float)
        X = np.asarray(points, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"solve_p3p: bearings/points are not numeric arrays ({exc})") from None
    if f.ndim != 3 or f.shape[1:] != (3, 3):
        raise ValueError(f"solve_p3p: bearings must have shape (N,3,3), got {f.shape}")
    if X.shape != f.shape:
        raise ValueError(
            f"solve_p3p: points must have shape {f.shape} like bearings, got {X.shape}"
        )
    return f, X


def _prepare(f, X, config: P3PConfig):
    """SoA unit bearings F and points P centred on their mean (conditioning), the mean, the
    (N,) degenerate mask and the squared longest side; degenerate rows get a harmless stand-in."""
    n = f.shape[0]
    finite = np.isfinite(f.reshape(n, 9).sum(axis=1) + X.reshape(n, 9).sum(axis=1))  # inf-inf = nan
    if not finite.all():
        f = np.where(finite[:, None, None], f, _SAFE_F)
        X = np.where(finite[:, None, None], X, _SAFE_X)
    F, P = soa(f), soa(X)
    norms = [vnorm(v) for v in F]
    F = tuple(vscale(v, 1.0 / nv) for v, nv in zip(F, norms))
    origin = tuple((P[0][k] + P[1][k] + P[2][k]) / 3.0 for k in range(3))
    P = tuple(vsub(v, origin) for v in P)
    bad = ~finite
    for nv in norms:
        bad |= ~(nv[:, 0] > 1e-12)
    for i, j in ((0, 1), (0, 2), (1, 2)):
        bad |= ~(vnorm(vcross(F[i], F[j]))[:, 0] >= config.min_bearing_sine)
    d12, d13, d23 = vsub(P[1], P[0]), vsub(P[2], P[0]), vsub(P[2], P[1])
    longest2 = np.maximum(np.maximum(vdot(d12, d12), vdot(d13, d13)), vdot(d23, d23))[:, 0]
    area2 = vnorm(vcross(d12, d13))[:, 0]
    bad |= ~(longest2 > 0) | ~(area2 >= config.min_triangle_ratio * longest2)
    origin = np.concatenate(origin, axis=1)
    if bad.any():  # rare path: redo with the stand-in rows
        keep = ~bad[:, None, None]
        F2, P2, origin2, _, longest2b = _prepare(
            np.where(keep, f, _SAFE_F), np.where(keep, X, _SAFE_X), config
        )
        return F2, P2, np.where(bad[:, None], 0.0, origin2), bad, longest2b
    return F, P, origin, bad, longest2


# ----------------------------------------------------------------------------- shared steps


def _triangle_frame(p0, p1, p2):
    """Orthonormal frame (columns e1, e2, e3) of the triangle p0 p1 p2."""
    d1 = vsub(p1, p0)
    e1 = vunit(d1)
    e3 = vunit(vcross(d1, vsub(p2, p0)))
    return e1, vcross(e3, e1), e3


def _pose_from_depths(F, FP, lam):
    """R_wc, t_wc taking the camera-frame points l_i f_i onto the (centred, mean-zero) world
    points P_i, exact for consistent depths: R = F_P F_Y^T from the two triangle frames (FP of
    the world triangle, given), t = -R mean(Y). R as rows of 3-tuples."""
    Y = [vscale(F[i], lam[i]) for i in range(3)]
    FY = _triangle_frame(*Y)
    R = tuple(
        tuple(FP[0][i] * FY[0][j] + FP[1][i] * FY[1][j] + FP[2][i] * FY[2][j] for j in range(3))
        for i in range(3)
    )
    ybar = tuple(Y[0][k] + Y[1][k] + Y[2][k] for k in range(3))
    t = tuple(
        (R[i][0] * ybar[0] + R[i][1] * ybar[1] + R[i][2] * ybar[2]) * (-1.0 / 3.0) for i in range(3)
    )
    return R, t


def _reprojection_check(F, P, R, t):
    """Largest angle (M,) between the world ray P_i - t and the rotated bearing R f_i, and whether
    every point lies ahead along its bearing. sin^2 = 1 - cos^2 resolves angles down to ~1e-8 rad,
    far below the acceptance threshold."""
    worst = 0.0
    ahead = True
    for p in range(3):
        d = vsub(P[p], t)
        g = tuple(R[i][0] * F[p][0] + R[i][1] * F[p][1] + R[i][2] * F[p][2] for i in range(3))
        along = vdot(d, g)
        worst = np.maximum(worst, 1.0 - along * along / vdot(d, d))
        ahead = ahead & (along > 0)
    residual = np.arcsin(np.sqrt(np.clip(worst, 0.0, 1.0)))
    return np.where(np.isfinite(residual), residual, np.inf), ahead


def _assemble(R, t, residual, ok_m, inst, origin, degenerate, method, lim2) -> P3PCandidates:
    """Flat candidates (sorted by instance) -> P3PCandidates: drop duplicates (camera centre
    closer than sqrt(lim2) to an earlier candidate of the same instance: three bearings of a
    non-degenerate triangle fix R given the centre), valid ones first, world origin restored."""
    N = degenerate.shape[0]
    keep = ok_m.copy()
    for lag in range(1, MAX_CANDIDATES):
        same = inst[lag:] == inst[:-lag]
        d2 = (
            (t[0][lag:] - t[0][:-lag]) ** 2
            + (t[1][lag:] - t[1][:-lag]) ** 2
            + (t[2][lag:] - t[2][:-lag]) ** 2
        )
        keep[lag:] &= ~(same & ok_m[:-lag] & (d2 < lim2[lag:]))
    owner = inst[keep]
    count = np.bincount(owner, minlength=N)
    start = np.cumsum(count) - count
    row = owner * MAX_CANDIDATES + (np.arange(owner.size) - start[owner])
    R_out = np.zeros((N * MAX_CANDIDATES, 9))
    t_out = np.zeros((N * MAX_CANDIDATES, 3))
    res_out = np.full(N * MAX_CANDIDATES, np.inf)
    every = bool(keep.all())  # the common case: skip the boolean gathers
    R_out[row] = np.stack(
        [R[i][j] if every else R[i][j][keep] for i in range(3) for j in range(3)], axis=-1
    )
    t_out[row] = np.stack([x if every else x[keep] for x in t], axis=-1) + origin[owner]
    res_out[row] = residual if every else residual[keep]
    valid = np.arange(MAX_CANDIDATES) < count[:, None]
    return P3PCandidates(
        R_wc=R_out.reshape(N, MAX_CANDIDATES, 3, 3),
        t_wc=t_out.reshape(N, MAX_CANDIDATES, 3),
        valid=valid,
        residual=res_out.reshape(N, MAX_CANDIDATES),
        degenerate=degenerate,
        method=method,
    )


def _polish_pose(F, P, R, t, iters):
    """Gauss-Newton on the pose: 6 tangent-plane bearing residuals, 6 unknowns (left perturbation
    of the world-to-camera transform), batched over all M candidates (flat SoA in and out)."""
    Fm = np.stack([np.stack(v, axis=-1) for v in F], axis=1)  # (M,3,3) rows = bearings
    Pm = np.stack([np.stack(v, axis=-1) for v in P], axis=1)
    Rcw = np.stack([np.stack(row, axis=-1) for row in R], axis=-1)  # transpose of R_wc
    tcw = -np.einsum("mij,mj->mi", Rcw, np.stack(t, axis=-1))
    helper = np.where(np.abs(Fm[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    B1 = np.cross(Fm, helper)
    B1 /= np.linalg.norm(B1, axis=-1, keepdims=True)
    Bt = np.stack([B1, np.cross(Fm, B1)], axis=-2)  # (M,3,2,3) tangent basis per bearing
    for _ in range(iters):
        Xc = np.einsum("mij,mpj->mpi", Rcw, Pm) + tcw[:, None, :]
        nrm = np.linalg.norm(Xc, axis=-1, keepdims=True)
        u = Xc / nrm
        rp = np.einsum("mpkj,mpj->mpk", Bt, u)  # (M,3,2) residual per point
        # d r / d Xc = Bt (I - u u^T) / |Xc| = (Bt - r u^T) / |Xc| =: G; d Xc = Xc x dtheta + dt,
        # so the Jacobian rows are [Xc x g, g] for each row g of G
        G = (Bt - rp[..., :, None] * u[..., None, :]) / nrm[..., None]  # (M,3,2,3)
        J = np.concatenate([np.cross(Xc[..., None, :], G), G], axis=-1).reshape(-1, 6, 6)
        r = rp.reshape(-1, 6)
        J = np.nan_to_num(J)
        try:
            step = np.linalg.solve(J, -np.nan_to_num(r)[..., None])[..., 0]
        except np.linalg.LinAlgError:  # some singular Jacobian in the batch: least squares for all
            step = (np.linalg.pinv(J) @ -np.nan_to_num(r)[..., None])[..., 0]
        step = np.where(np.isfinite(step).all(axis=1, keepdims=True), step, 0.0)
        dR = Rotation.from_rotvec(step[:, :3]).as_matrix()
        Rcw = dR @ Rcw
        tcw = np.einsum("mij,mj->mi", dR, tcw) + step[:, 3:]
    return _soa_pose(np.swapaxes(Rcw, -1, -2), -np.einsum("mji,mj->mi", Rcw, tcw))


def _soa_pose(Ra, ta):
    """(...,3,3), (...,3) arrays -> R as rows of 3-tuples, t as a 3-tuple."""
    return (
        tuple(tuple(Ra[..., i, j] for j in range(3)) for i in range(3)),
        tuple(ta[..., i] for i in range(3)),
    )
