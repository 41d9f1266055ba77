"""Perspective-three-point (P3P): every camera pose consistent with three bearings of three
known world points, batched over N instances in numpy (no Python loop per instance).

Methods (all return every real candidate, up to four per instance):
- ``lambdatwist`` (default): Persson & Nordberg, "Lambda Twist", ECCV 2018 -- one real root of
  the cubic that makes the pencil of two depth conics degenerate, closed-form eigenvectors of
  that rank-2 conic, its two planes, a quadratic on each, Gauss-Newton on the depths.
- ``grunert``: Grunert 1841 as reviewed by Haralick et al. 1991 (the solver of seed
  004_fa12d1d18dcbd0db.txt, section II-B, eq. 1): quartic in v = s3/s1.
- ``finsterwalder``: seed 000_05137a0a9c449be3.txt, section III-B, eqs. (1)-(10): a root of the
  cubic (10) makes (8) a line pair, (9) gives v linear in u, (7) a quadratic in u. (The middle
  fraction of eq. (5) has numerator b^2, from (2); the seed prints a^2.)
- ``kneip``: Kneip, Scaramuzza & Siegwart, CVPR 2011 (seed 001_0f8f8dae37ce6b79.txt,
  section III-C, ref. [18]): quartic in cos(theta) in intermediate camera/world frames, camera
  centre and orientation in closed form.

Conventions: ``bearings`` (N,3,3), row i = direction to world point i in the camera frame
(normalized here); ``points`` (N,3,3), row i = world point i. Output: pose of the camera in the
world, X_i = R_wc @ (depth_i * f_i) + t_wc. Malformed shapes raise ValueError; degenerate
geometry (NaN/inf, zero or parallel bearings, coincident or collinear points) gives rows with
``valid`` all False and ``degenerate`` True. Every returned candidate has positive depths and
reprojects the three points within ``P3PConfig.max_residual_rad``.

Implementation note: the hot path keeps vectors as tuples of three arrays (structure of arrays):
per-instance quantities are (N,1) columns, and after the polynomial stage only the M candidates
that exist are kept as flat (M,) arrays, so numpy does one pass per scalar operation over all of
them. Large batches run in cache-sized blocks of BLOCK instances.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.candidates import CandidateSet
from graphloc.config import check

METHODS = ("lambdatwist", "grunert", "finsterwalder", "kneip")
MAX_CANDIDATES = 4
BLOCK = 4096  # instances per vectorized pass (cache-sized)


@dataclass(frozen=True)
class P3PConfig:
    """Thresholds of the solver (angles in radians, lengths relative to the longest side)."""

    min_bearing_sine: float = 1e-6  # |f_i x f_j| below this -> parallel bearings, degenerate
    min_triangle_ratio: float = 1e-6  # |d12 x d13| / longest^2 below this -> collinear points
    max_residual_rad: float = 1e-6  # reprojection check on every returned candidate
    duplicate_tol: float = 1e-7  # candidate centres closer than this * longest side merge
    depth_refine_iters: int | None = None  # Gauss-Newton steps on the depths; None: per method
    # (lambdatwist 1: its depths are accurate to ~1e-10 before; grunert, finsterwalder 2)
    polish_iters: int = 2  # Gauss-Newton steps on the pose when polish=True

    def __post_init__(self):
        check(
            self,
            nonnegative=("min_bearing_sine", "min_triangle_ratio", "duplicate_tol"),
            positive=("max_residual_rad",),
            integer={"depth_refine_iters": 0, "polish_iters": 0},
            optional=("depth_refine_iters",),
        )


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
    bearings,
    points,
    method: str = "lambdatwist",
    polish: bool = False,
    config: P3PConfig = P3PConfig(),
) -> P3PCandidates:
    """All P3P candidates of N instances; bearings, points (N,3,3). See the module docstring."""
    if method not in METHODS:
        raise ValueError(f"solve_p3p: unknown method {method!r}; choose one of {METHODS}")
    f, X = _check_shapes(bearings, points)
    if f.shape[0] <= BLOCK:
        return _solve_block(f, X, method, polish, config)
    # blocks that fit the CPU cache are ~2x faster than one pass over 100k instances
    parts = [
        _solve_block(f[s : s + BLOCK], X[s : s + BLOCK], method, polish, config)
        for s in range(0, f.shape[0], BLOCK)
    ]
    return P3PCandidates(
        **{
            name: np.concatenate([getattr(p, name) for p in parts])
            for name in ("R_wc", "t_wc", "valid", "residual", "degenerate")
        },
        method=method,
    )


def _solve_block(f, X, method, polish, config) -> P3PCandidates:
    """solve_p3p on one block; numpy warnings are suppressed and bad values masked instead."""
    with np.errstate(all="ignore"):
        F, P, origin, degenerate, longest2 = _prepare(f, X, config)
        if method == "kneip":
            R, t, inst = _kneip(F, P)
            F, P = _gather(F, inst), _gather(P, inst)
            ok_m = np.ones(inst.size, bool)
        else:
            solver = {
                "lambdatwist": _lambdatwist_depths,
                "grunert": _grunert_depths,
                "finsterwalder": _finsterwalder_depths,
            }[method]
            geo = _geometry(F, P)
            FP = _triangle_frame(*P)  # world triangle frame, per instance
            lam, ok = solver(geo)
            # from here on only the candidates that exist: flat arrays of length M, sorted by
            # instance
            inst, slot = np.nonzero(ok)
            lam = tuple(x[inst, slot] for x in lam)
            F, P = _gather(F, inst), _gather(P, inst)
            geo = tuple(x[inst, 0] for x in geo)
            iters = config.depth_refine_iters
            lam = _refine_depths(
                geo, lam, (1 if method == "lambdatwist" else 2) if iters is None else iters
            )
            ok_m = (lam[0] > 0) & (lam[1] > 0) & (lam[2] > 0)
            R, t = _pose_from_depths(F, _gather(FP, inst), lam)
        if polish:
            R, t = _polish_pose(F, P, R, t, config.polish_iters)
        residual, in_front = _reprojection_check(F, P, R, t)
        ok_m &= in_front & (residual < config.max_residual_rad) & ~degenerate[inst]
        lim2 = config.duplicate_tol**2 * longest2[inst]
        return _assemble(R, t, residual, ok_m, inst, origin, degenerate, method, lim2)


def solve_p3p_poses(
    bearings, points, method: str = "lambdatwist", polish: bool = False
) -> list[gtsam.Pose3]:
    """Convenience for one instance: bearings, points (3,3) -> valid candidates as gtsam.Pose3."""
    b = np.asarray(bearings, dtype=float)
    p = np.asarray(points, dtype=float)
    if b.shape != (3, 3) or p.shape != (3, 3):
        raise ValueError(
            f"solve_p3p_poses: bearings and points must be (3,3), got {b.shape} and {p.shape}"
        )
    return solve_p3p(b[None], p[None], method=method, polish=polish).poses(0)


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
    F, P = _soa(f), _soa(X)
    norms = [_vnorm(v) for v in F]
    F = tuple(_vscale(v, 1.0 / nv) for v, nv in zip(F, norms))
    origin = tuple((P[0][k] + P[1][k] + P[2][k]) / 3.0 for k in range(3))
    P = tuple(_vsub(v, origin) for v in P)
    bad = ~finite
    for nv in norms:
        bad |= ~(nv[:, 0] > 1e-12)
    for i, j in ((0, 1), (0, 2), (1, 2)):
        bad |= ~(_vnorm(_vcross(F[i], F[j]))[:, 0] >= config.min_bearing_sine)
    d12, d13, d23 = _vsub(P[1], P[0]), _vsub(P[2], P[0]), _vsub(P[2], P[1])
    longest2 = np.maximum(np.maximum(_vdot(d12, d12), _vdot(d13, d13)), _vdot(d23, d23))[:, 0]
    area2 = _vnorm(_vcross(d12, d13))[:, 0]
    bad |= ~(longest2 > 0) | ~(area2 >= config.min_triangle_ratio * longest2)
    origin = np.concatenate(origin, axis=1)
    if bad.any():  # rare path: redo with the stand-in rows
        keep = ~bad[:, None, None]
        F2, P2, origin2, _, longest2b = _prepare(
            np.where(keep, f, _SAFE_F), np.where(keep, X, _SAFE_X), config
        )
        return F2, P2, np.where(bad[:, None], 0.0, origin2), bad, longest2b
    return F, P, origin, bad, longest2


def _soa(A):
    """(N,3,3) rows of vectors -> tuple of 3 vectors, each a tuple of 3 contiguous (N,1) arrays."""
    T = np.ascontiguousarray(A.transpose(1, 2, 0))[..., None]
    return tuple((T[p, 0], T[p, 1], T[p, 2]) for p in range(3))


def _vdot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _vcross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _vsub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _vscale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


def _vnorm(a):
    return np.sqrt(_vdot(a, a))


def _vunit(a):
    return _vscale(a, 1.0 / _vnorm(a))


def _geometry(F, P):
    """Cosines between bearings and squared side lengths c12, c13, c23, a12, a13, a23 ((N,1)
    each)."""
    d12, d13, d23 = _vsub(P[0], P[1]), _vsub(P[0], P[2]), _vsub(P[1], P[2])
    return (
        _vdot(F[0], F[1]),
        _vdot(F[0], F[2]),
        _vdot(F[1], F[2]),
        _vdot(d12, d12),
        _vdot(d13, d13),
        _vdot(d23, d23),
    )


# ----------------------------------------------------------------------------- polynomial roots


def _real_cubic_roots(b, c, d, newton_steps: int = 1, largest_only: bool = False):
    """Real roots of x^3 + b x^2 + c x + d, coefficients of any (broadcastable) shape S ->
    (*S, 3), largest first, NaN where not real (largest_only: (*S,) the largest root alone,
    which is all lambdatwist and Ferrari need -- the hot path). Trigonometric form for three
    real roots, Cardano for one; then Newton steps."""
    b, c, d = (np.asarray(v, dtype=float) for v in (b, c, d))
    if not largest_only:
        b, c, d = b[..., None], c[..., None], d[..., None]
    p = c - b * b / 3.0
    q = 2.0 * b**3 / 27.0 - b * c / 3.0 + d
    disc = (q / 2.0) ** 2 + (p / 3.0) ** 3
    shift = -b / 3.0
    three = disc < 0
    m = 2.0 * np.sqrt(np.maximum(-p / 3.0, 0.0))
    phi = np.arccos(np.clip(np.where(three, 3.0 * q / (p * m), 0.0), -1.0, 1.0)) / 3.0
    sq = np.sqrt(np.maximum(disc, 0.0))
    single = np.cbrt(-q / 2.0 + sq) + np.cbrt(-q / 2.0 - sq) + shift
    if largest_only:
        x = np.where(three, m * np.cos(phi) + shift, single)
    else:
        cphi, sphi = np.cos(phi), np.sin(phi) * (np.sqrt(3.0) / 2.0)
        # cos(phi - 2 pi k / 3) for k = 0, 1, 2 (k = 0 is the largest)
        trig = m * np.concatenate([cphi, -0.5 * cphi + sphi, -0.5 * cphi - sphi], axis=-1) + shift
        x = np.where(three, trig, np.where(np.arange(3) == 0, single, np.nan))
    for _ in range(newton_steps):
        fx = ((x + b) * x + c) * x + d
        dfx = (3.0 * x + 2.0 * b) * x + c
        x = x - np.where(dfx != 0, fx / dfx, 0.0)
    return x


def _largest_real_cubic_root(b, c, d):
    """Largest real root (shape of the coefficients) of x^3 + b x^2 + c x + d; two Newton steps."""
    return _real_cubic_roots(b, c, d, newton_steps=2, largest_only=True)


def _real_quartic_roots(coeffs):
    """Real roots of sum_k coeffs[:, k] x^(4-k), coeffs (N,5) -> (N,4), NaN where complex.
    Ferrari: depressed quartic y^4 + p y^2 + q y + r (x = y - b/4), largest root m >= 0 of the
    resolvent cubic m^3 + p m^2 + (p^2/4 - r) m - q^2/8 = 0 splits it into two quadratics
    y^2 -+ sqrt(2m) y + p/2 + m +- q / (2 sqrt(2m)); a slightly negative discriminant (rounding)
    counts as a double root -- every candidate is verified downstream. Two Newton steps."""
    a = coeffs / coeffs[:, :1]
    b, c, d, e = a[:, 1:2], a[:, 2:3], a[:, 3:4], a[:, 4:5]
    b2 = b * b
    p = c - 0.375 * b2
    q = d - 0.5 * b * c + 0.125 * b2 * b
    r = e - 0.25 * b * d + 0.0625 * b2 * c - (3.0 / 256.0) * b2 * b2
    m = np.maximum(_largest_real_cubic_root(p, 0.25 * p * p - r, -0.125 * q * q), 0.0)
    w = np.sqrt(2.0 * m)
    scale = 1.0 + np.abs(p) + np.sqrt(np.abs(r))
    biquadratic = w <= 1e-12 * scale
    roots = []
    for sign in (1.0, -1.0):
        # y^2 + B y + C = 0
        B = -sign * w
        C = 0.5 * p + m + sign * q / np.where(biquadratic, 1.0, 2.0 * w)
        disc = B * B - 4.0 * C
        real = disc >= -1e-9 * (B * B + np.abs(C) + 1.0)
        sq = np.sqrt(np.maximum(disc, 0.0))
        roots += [np.where(real, 0.5 * (-B + sq), np.nan), np.where(real, 0.5 * (-B - sq), np.nan)]
        # q ~ 0: y^2 = (-p +- sqrt(p^2 - 4r)) / 2
        z2 = 0.5 * (-p + sign * np.sqrt(p * p - 4.0 * r))  # NaN when complex
        zq = np.sqrt(np.where(z2 >= 0, z2, np.nan))
        roots[-2] = np.where(biquadratic, zq, roots[-2])
        roots[-1] = np.where(biquadratic, -zq, roots[-1])
    x = np.concatenate(roots, axis=1) - 0.25 * b
    for _ in range(2):
        fx = (((x + b) * x + c) * x + d) * x + e
        dfx = ((4.0 * x + 3.0 * b) * x + 2.0 * c) * x + d
        x = x - np.where(dfx != 0, fx / dfx, 0.0)
    return x


# ----------------------------------------------------------------------------- lambdatwist


def _lambdatwist_depths(geo):
    """Persson & Nordberg 2018: depths (l1, l2, l3) of up to 4 candidates ((N,4) each) and mask.

    lambda^T M_ij lambda = a_ij, M_ij the quadratic form of |l_i f_i - l_j f_j|^2.
    D1 = a23 M12 - a12 M23 and D2 = a23 M13 - a13 M23 vanish on every solution; D0 = D1 + g D2 is
    degenerate for the real roots g of det(D1 + g D2) = 0, and when indefinite it is a pair of
    planes through the origin holding the solutions. Any real root serves when real solutions
    exist (one real root: it is the real line pair; three: all are), we take the largest."""
    c12, c13, c23, a12, a13, a23 = geo
    z = np.zeros_like(c12)
    # symmetric 3x3 as entries (00, 01, 02, 11, 12, 22)
    D1 = (a23, -c12 * a23, z, a23 - a12, c23 * a12, -a12)
    D2 = (a23, z, -c13 * a23, -a13, c23 * a13, a23 - a13)
    det2 = _sym_det(D2)
    g = _largest_real_cubic_root(
        _sym_trace_adj(D2, D1) / det2, _sym_trace_adj(D1, D2) / det2, _sym_det(D1) / det2
    )
    D0 = tuple(e1 + g * e2 for e1, e2 in zip(D1, D2))
    tr = D0[0] + D0[3] + D0[5]
    pm = _sym_principal_minors(D0)  # = sigma1 * sigma2 (third eigenvalue is 0)
    s1 = 0.5 * (
        tr + np.copysign(np.sqrt(np.maximum(tr * tr - 4.0 * pm, 0.0)), tr)
    )  # larger |sigma|
    s2 = pm / s1
    e0 = _sym_null_vector(D0)
    e1 = _rank1_direction(D0, s2, e0)
    e2 = _vcross(e0, e1)
    ratio = np.sqrt(np.maximum(-s2 / s1, 0.0))
    indefinite = pm < 0
    asum = a12 + a13 + a23
    D1e0, D1e1, D1e2 = _sym_apply(D1, e0), _sym_apply(D1, e1), _sym_apply(D1, e2)
    q00 = _vdot(e0, D1e0)
    lams, oks = [], []
    for sign in (1.0, -1.0):
        # D0 = s1 e1e1' + s2 e2e2': plane (e1 - sign*ratio*e2).l = 0 is spanned by e0 and v;
        # on it l = a e0 + b v and l' D1 l = q00 a^2 + 2 q01 a b + q11 b^2 = 0
        w = sign * ratio
        v = tuple(w * a + b for a, b in zip(e1, e2))
        q01 = _vdot(v, D1e0)
        q11 = _vdot(v, tuple(w * a + b for a, b in zip(D1e1, D1e2)))
        disc = q01 * q01 - q00 * q11
        k = -(q01 + np.copysign(np.sqrt(np.maximum(disc, 0.0)), q01))
        for alpha, beta in ((q11, k), (k, q00)):  # the two roots, in the cancellation-free form
            d = tuple(alpha * a + beta * b for a, b in zip(e0, v))
            # scale so that sum_ij |l_i f_i - l_j f_j|^2 = a12 + a13 + a23, with sum(l) > 0
            norm2 = 2.0 * (_vdot(d, d) - c12 * d[0] * d[1] - c13 * d[0] * d[2] - c23 * d[1] * d[2])
            s = np.copysign(np.sqrt(asum / norm2), d[0] + d[1] + d[2])
            lam = _vscale(d, s)
            lams.append(lam)
            oks.append(indefinite & (disc >= 0) & (lam[0] > 0) & (lam[1] > 0) & (lam[2] > 0))
    return tuple(
        np.concatenate([lam[i] for lam in lams], axis=1) for i in range(3)
    ), np.concatenate(oks, axis=1)


def _sym_det(A):
    a, b, c, d, e, f = A
    return a * (d * f - e * e) - b * (b * f - c * e) + c * (b * e - c * d)


def _sym_trace_adj(A, B):
    """trace(adj(A) @ B) for symmetric A, B (6-entry form): det(A + gB) = det A + g tr(adj(A) B)
    + g^2 tr(adj(B) A) + g^3 det B."""
    a, b, c, d, e, f = A
    j = (d * f - e * e, c * e - b * f, b * e - c * d, a * f - c * c, b * c - a * e, a * d - b * b)
    return j[0] * B[0] + j[3] * B[3] + j[5] * B[5] + 2.0 * (j[1] * B[1] + j[2] * B[2] + j[4] * B[4])


def _sym_principal_minors(A):
    a, b, c, d, e, f = A
    return (a * d - b * b) + (a * f - c * c) + (d * f - e * e)


def _sym_null_vector(A):
    """Unit null vector of a rank-2 symmetric A (6-entry form): the longest cross product of
    two of its rows."""
    a, b, c, d, e, f = A
    r0, r1, r2 = (a, b, c), (b, d, e), (c, e, f)
    x01, x02, x12 = _vcross(r0, r1), _vcross(r0, r2), _vcross(r1, r2)
    n01, n02, n12 = _vdot(x01, x01), _vdot(x02, x02), _vdot(x12, x12)
    use01 = (n01 >= n02) & (n01 >= n12)
    use02 = ~use01 & (n02 >= n12)
    return _vunit(
        tuple(np.where(use01, p, np.where(use02, q, r)) for p, q, r in zip(x01, x02, x12))
    )


def _rank1_direction(A, s2, e0):
    """For rank-2 symmetric A = s1 e1e1' + s2 e2e2' with null vector e0:
    A - s2 I + s2 e0e0' = (s1 - s2) e1e1', so e1 is its column with the largest diagonal entry."""
    a, b, c, d, e, f = A
    m00, m11, m22 = a - s2 + s2 * e0[0] ** 2, d - s2 + s2 * e0[1] ** 2, f - s2 + s2 * e0[2] ** 2
    m01, m02, m12 = b + s2 * e0[0] * e0[1], c + s2 * e0[0] * e0[2], e + s2 * e0[1] * e0[2]
    d0, d1, d2 = np.abs(m00), np.abs(m11), np.abs(m22)
    use0 = (d0 >= d1) & (d0 >= d2)
    use1 = ~use0 & (d1 >= d2)
    col = tuple(
        np.where(use0, x, np.where(use1, y, w))
        for x, y, w in ((m00, m01, m02), (m01, m11, m12), (m02, m12, m22))
    )
    return _vunit(col)


def _sym_apply(A, v):
    """A @ v for symmetric A (6-entry form)."""
    a, b, c, d, e, f = A
    return (
        a * v[0] + b * v[1] + c * v[2],
        b * v[0] + d * v[1] + e * v[2],
        c * v[0] + e * v[1] + f * v[2],
    )


# ----------------------------------------------------------------------------- Grunert / Haralick


def _grunert_depths(geo):
    """Grunert's quartic (Haralick et al. 1991, sec. 2; seed 004 eq. 1), s2 = u s1, s3 = v s1.
    Side a = |P2-P3| faces alpha = angle(f2, f3), b = |P1-P3| faces beta, c = |P1-P2| gamma."""
    cg, cb, ca, c2, b2, a2 = geo
    amc, apc = (a2 - c2) / b2, (a2 + c2) / b2
    A4 = (amc - 1.0) ** 2 - 4.0 * c2 / b2 * ca * ca
    A3 = 4.0 * (amc * (1.0 - amc) * cb - (1.0 - apc) * ca * cg + 2.0 * c2 / b2 * ca * ca * cb)
    A2 = 2.0 * (
        amc**2
        - 1.0
        + 2.0 * amc**2 * cb * cb
        + 2.0 * (b2 - c2) / b2 * ca * ca
        - 4.0 * apc * ca * cb * cg
        + 2.0 * (b2 - a2) / b2 * cg * cg
    )
    A1 = 4.0 * (-amc * (1.0 + amc) * cb + 2.0 * a2 / b2 * cg * cg * cb - (1.0 - apc) * ca * cg)
    A0 = (1.0 + amc) ** 2 - 4.0 * a2 / b2 * cg * cg
    v = _real_quartic_roots(np.concatenate([A4, A3, A2, A1, A0], axis=1))  # (N,4)
    u = (((amc - 1.0) * v - 2.0 * amc * cb) * v + 1.0 + amc) / (2.0 * (cg - v * ca))
    s1 = np.sqrt(b2 / (1.0 + v * v - 2.0 * v * cb))
    lam = (s1, u * s1, v * s1)
    ok = np.isfinite(v) & np.isfinite(u) & np.isfinite(s1) & (s1 > 0) & (u > 0) & (v > 0)
    return tuple(np.nan_to_num(x) for x in lam), ok


# ----------------------------------------------------------------------------- Finsterwalder


def _finsterwalder_depths(geo):
    """Seed 000 sec. III-B: a real root lambda of (10) makes (8) the line pair v = m u + n (9);
    each line in (7) gives a quadratic in u; s1 from (5), s2 = u s1, s3 = v s1 (4). Of the real
    roots we take the one whose line pair is most clearly real."""
    cg, cb, ca, c2, b2, a2 = geo
    sa2, sb2, sg2 = 1.0 - ca * ca, 1.0 - cb * cb, 1.0 - cg * cg
    G = c2 * (c2 * sb2 - b2 * sg2)
    H = b2 * (b2 - a2) * sg2 + c2 * (c2 + 2.0 * a2) * sb2 + 2.0 * b2 * c2 * (-1.0 + ca * cb * cg)
    I_ = b2 * (b2 - c2) * sa2 + a2 * (a2 + 2.0 * c2) * sb2 + 2.0 * a2 * b2 * (-1.0 + ca * cb * cg)
    J = a2 * (a2 * sb2 - b2 * sa2)
    lam0 = _real_cubic_roots(H / G, I_ / G, J / G).reshape(-1, 3)  # (N,3)
    B = -ca
    A = 1.0 + lam0
    C = (b2 - a2 - lam0 * c2) / b2
    D = -lam0 * cg
    E = (a2 + lam0 * c2) / b2 * cb
    Fc = (-a2 + lam0 * (b2 - c2)) / b2
    p2, q2 = B * B - A * C, E * E - C * Fc
    quality = np.where(np.isfinite(lam0), np.minimum(p2, q2) / (np.abs(p2) + np.abs(q2)), -np.inf)
    best = np.argmax(quality, axis=1)[:, None]
    C, D, E, p2, q2 = (np.take_along_axis(x, best, axis=1) for x in (C, D, E, p2, q2))
    p = np.sqrt(np.maximum(p2, 0.0))
    q = np.copysign(np.sqrt(np.maximum(q2, 0.0)), B * E - C * D)
    k = c2 / b2
    lams, oks = [], []
    for sign in (1.0, -1.0):
        m = (-B + sign * p) / C
        n = (-E + sign * q) / C
        # (7) with v = m u + n:  qa u^2 + 2 qb u + qc = 0
        qa = 1.0 - k * m * m
        qb = k * m * (cb - n) - cg
        qc = -k * n * n + 2.0 * k * n * cb + (b2 - c2) / b2
        disc = qb * qb - qa * qc
        r = -(qb + np.copysign(np.sqrt(np.maximum(disc, 0.0)), qb))
        for u in (r / qa, qc / r):
            v = m * u + n
            s1 = np.sqrt(b2 / (1.0 + v * v - 2.0 * v * cb))
            lam = (s1, u * s1, v * s1)
            ok = (
                (disc >= 0)
                & (p2 >= 0)
                & (q2 >= 0)
                & np.isfinite(u)
                & np.isfinite(v)
                & np.isfinite(s1)
            )
            lams.append(tuple(np.nan_to_num(x) for x in lam))
            oks.append(ok & (s1 > 0) & (u > 0) & (v > 0))
    return tuple(
        np.concatenate([lam[i] for lam in lams], axis=1) for i in range(3)
    ), np.concatenate(oks, axis=1)


# ----------------------------------------------------------------------------- Kneip


def _kneip(F, P):
    """Kneip et al. 2011: intermediate camera frame tau (f1, f1 x f2) and world frame eta
    (P1, P2, P3 plane); quartic in cos(theta), the angle of the eta plane about the P1-P2 axis;
    camera centre C and orientation R = N^T Q^T T in closed form (paper eqs. for C and Q).
    Returns flat candidates: R_wc (rows of 3-tuples), t_wc (3-tuple), instance index (M,)."""
    f1, f2, f3 = F
    P1, P2, P3 = P
    # the paper assumes f3 on the negative-z side of the tau frame: swap 1 <-> 2 otherwise
    swap = _vdot(_vcross(f1, f2), f3) > 0
    f1, f2 = (
        tuple(np.where(swap, b, a) for a, b in zip(f1, f2)),
        tuple(np.where(swap, a, b) for a, b in zip(f1, f2)),
    )
    P1, P2 = (
        tuple(np.where(swap, b, a) for a, b in zip(P1, P2)),
        tuple(np.where(swap, a, b) for a, b in zip(P1, P2)),
    )
    tx = f1
    tz = _vunit(_vcross(f1, f2))
    ty = _vcross(tz, tx)
    f3t = (_vdot(tx, f3), _vdot(ty, f3), _vdot(tz, f3))
    d12v = _vsub(P2, P1)
    d12 = _vnorm(d12v)
    nx = _vscale(d12v, 1.0 / d12)
    nz = _vunit(_vcross(nx, _vsub(P3, P1)))
    ny = _vcross(nz, nx)
    p1, p2 = _vdot(nx, _vsub(P3, P1)), _vdot(ny, _vsub(P3, P1))
    cos_beta = _vdot(f1, f2)
    b = np.copysign(np.sqrt(1.0 / (1.0 - cos_beta**2) - 1.0), cos_beta)  # cot(beta)
    q1, q2 = f3t[0] / f3t[2], f3t[1] / f3t[2]  # phi1, phi2
    dd = d12
    a4 = -(q2**2) * p2**4 - q1**2 * p2**4 - p2**4
    a3 = 2 * p2**3 * dd * b + 2 * q2**2 * p2**3 * dd * b - 2 * q1 * q2 * p2**3 * dd
    a2 = (
        -(q2**2) * p1**2 * p2**2
        - q2**2 * p2**2 * dd**2 * b**2
        - q2**2 * p2**2 * dd**2
        + q2**2 * p2**4
        + q1**2 * p2**4
        + 2 * p1 * p2**2 * dd
        + 2 * q1 * q2 * p1 * p2**2 * dd * b
        - q1**2 * p1**2 * p2**2
        + 2 * q2**2 * p1 * p2**2 * dd
        - p2**2 * dd**2 * b**2
        - 2 * p1**2 * p2**2
    )
    a1 = (
        2 * p1**2 * p2 * dd * b
        + 2 * q1 * q2 * p2**3 * dd
        - 2 * q2**2 * p2**3 * dd * b
        - 2 * p1 * p2 * dd**2 * b
    )
    a0 = (
        -2 * q1 * q2 * p1 * p2**2 * dd * b
        + q2**2 * p2**2 * dd**2
        + 2 * p1**3 * dd
        - p1**2 * dd**2
        + q2**2 * p1**2 * p2**2
        - p1**4
        - 2 * q2**2 * p1 * p2**2 * dd
        + q1**2 * p1**2 * p2**2
        + q2**2 * p2**2 * dd**2 * b**2
    )
    cos_t = _real_quartic_roots(np.concatenate([a4, a3, a2, a1, a0], axis=1))  # (N,4)
    inst, slot = np.nonzero(np.isfinite(cos_t) & (np.abs(cos_t) <= 1.0 + 1e-9))
    cos_t = np.clip(cos_t[inst, slot], -1.0, 1.0)
    q1, q2, p1, p2, dd, b = (x[inst, 0] for x in (q1, q2, p1, p2, dd, b))
    Nrows, Trows, P1 = (
        _gather((nx, ny, nz), inst),
        _gather((tx, ty, tz), inst),
        _gather((P1,), inst)[0],
    )
    sin_t = np.sqrt(1.0 - cos_t**2)
    cot_a = (-q1 * p1 / q2 - cos_t * p2 + dd * b) / (-q1 * cos_t * p2 / q2 + p1 - dd)
    sin_a = np.sqrt(1.0 / (cot_a**2 + 1.0))
    cos_a = np.copysign(np.sqrt(1.0 - sin_a**2), cot_a)
    w = dd * sin_a * (sin_a * b + cos_a)
    C_eta = (dd * cos_a * (sin_a * b + cos_a), cos_t * w, sin_t * w)
    t = tuple(
        P1[i] + Nrows[0][i] * C_eta[0] + Nrows[1][i] * C_eta[1] + Nrows[2][i] * C_eta[2]
        for i in range(3)
    )
    Q = (
        (-cos_a, -sin_a * cos_t, -sin_a * sin_t),
        (sin_a, -cos_a * cos_t, -cos_a * sin_t),
        (0.0, -sin_t, cos_t),
    )
    # A = N^T Q^T: A[i][j] = sum_k N[k][i] Q[j][k]; R = A T
    A = tuple(
        tuple(
            Nrows[0][i] * Q[j][0] + Nrows[1][i] * Q[j][1] + Nrows[2][i] * Q[j][2] for j in range(3)
        )
        for i in range(3)
    )
    R = tuple(
        tuple(
            A[i][0] * Trows[0][j] + A[i][1] * Trows[1][j] + A[i][2] * Trows[2][j] for j in range(3)
        )
        for i in range(3)
    )
    return R, t, inst


# ----------------------------------------------------------------------------- shared steps


def _refine_depths(geo, lam, iters):
    """Gauss-Newton on l_i^2 + l_j^2 - 2 c_ij l_i l_j = a_ij (3 equations, 3 unknowns) for every
    candidate (geo: _geometry per candidate); the Jacobian [[a, b, 0], [c, 0, d], [0, e, g]] is
    solved by its adjugate."""
    c12, c13, c23, a12, a13, a23 = geo
    l1, l2, l3 = lam
    for _ in range(iters):
        r0 = 0.5 * (l1 * l1 + l2 * l2 - a12) - c12 * l1 * l2
        r1 = 0.5 * (l1 * l1 + l3 * l3 - a13) - c13 * l1 * l3
        r2 = 0.5 * (l2 * l2 + l3 * l3 - a23) - c23 * l2 * l3
        a, b = l1 - c12 * l2, l2 - c12 * l1
        c, d = l1 - c13 * l3, l3 - c13 * l1
        e, g = l2 - c23 * l3, l3 - c23 * l2
        inv_det = -1.0 / (a * d * e + b * c * g)
        s1 = (-d * e * r0 - b * g * r1 + b * d * r2) * inv_det
        s2 = (-c * g * r0 + a * g * r1 - a * d * r2) * inv_det
        s3 = (c * e * r0 - a * e * r1 - b * c * r2) * inv_det
        good = np.isfinite(s1) & np.isfinite(s2) & np.isfinite(s3)
        l1, l2, l3 = (np.where(good, x - s, x) for x, s in ((l1, s1), (l2, s2), (l3, s3)))
    return l1, l2, l3


def _gather(V, inst):
    """Per-instance SoA vectors ((N,1) entries) -> per-candidate flat (M,) entries."""
    return tuple(tuple(x[inst, 0] for x in v) for v in V)


def _triangle_frame(p0, p1, p2):
    """Orthonormal frame (columns e1, e2, e3) of the triangle p0 p1 p2."""
    d1 = _vsub(p1, p0)
    e1 = _vunit(d1)
    e3 = _vunit(_vcross(d1, _vsub(p2, p0)))
    return e1, _vcross(e3, e1), e3


def _pose_from_depths(F, FP, lam):
    """R_wc, t_wc taking the camera-frame points l_i f_i onto the (centred, mean-zero) world
    points P_i, exact for consistent depths: R = F_P F_Y^T from the two triangle frames (FP of
    the world triangle, given), t = -R mean(Y). R as rows of 3-tuples."""
    Y = [_vscale(F[i], lam[i]) for i in range(3)]
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
        d = _vsub(P[p], t)
        g = tuple(R[i][0] * F[p][0] + R[i][1] * F[p][1] + R[i][2] * F[p][2] for i in range(3))
        along = _vdot(d, g)
        worst = np.maximum(worst, 1.0 - along * along / _vdot(d, d))
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
