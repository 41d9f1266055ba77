"""The seeds' P3P solvers, for the baselines and the P3P benchmark (graphloc itself uses Lambda
Twist, graphloc.geometry.p3p): Grunert 1841 as reviewed by Haralick et al. 1991 (seed 004
004_fa12d1d18dcbd0db.txt, Sec. II-B, eq. 1: a quartic in v = s3/s1); Finsterwalder (seed 000
000_05137a0a9c449be3.txt, Sec. III-B, eqs. (1)-(10): a root of the cubic (10) makes (8) a line
pair, (9) gives v linear in u, (7) a quadratic in u; the middle fraction of eq. (5) has
numerator b^2, from (2), where the seed prints a^2); Kneip, Scaramuzza & Siegwart, CVPR 2011
(seed 001 001_0f8f8dae37ce6b79.txt, Sec. III-C, ref. [18]: a quartic in cos(theta) in
intermediate camera/world frames, camera centre and orientation in closed form). Each is a
`solver` of graphloc.geometry.p3p.solve_p3p; `solve_p3p_by_name` picks one by its name."""

from __future__ import annotations

import numpy as np

from graphloc.geometry.p3p import P3PConfig, P3PCandidates, depth_candidates, lambdatwist, solve_p3p
from graphloc.geometry.p3p_soa import (
    gather,
    largest_real_cubic_root,
    vcross,
    vdot,
    vnorm,
    vscale,
    vsub,
    vunit,
)


def grunert(F, P, config):
    """Grunert's depths, refined twice (unless config says otherwise)."""
    iters = 2 if config.depth_refine_iters is None else config.depth_refine_iters
    return depth_candidates(F, P, grunert_depths, iters)


def finsterwalder(F, P, config):
    """Finsterwalder's depths, refined twice (unless config says otherwise)."""
    iters = 2 if config.depth_refine_iters is None else config.depth_refine_iters
    return depth_candidates(F, P, finsterwalder_depths, iters)


def kneip(F, P, config):
    """Kneip's poses in closed form (no depths to refine)."""
    R, t, inst = kneip_poses(F, P)
    return R, t, inst, np.ones(inst.size, bool)


SOLVERS = {f.__name__: f for f in (lambdatwist, grunert, finsterwalder, kneip)}
METHODS = tuple(SOLVERS)


def solve_p3p_by_name(
    bearings, points, method: str = "lambdatwist", polish: bool = False, config=P3PConfig()
) -> P3PCandidates:
    """graphloc.geometry.p3p.solve_p3p with the solver named `method` (one of METHODS)."""
    if method not in SOLVERS:
        raise ValueError(f"solve_p3p_by_name: unknown method {method!r}; choose one of {METHODS}")
    return solve_p3p(bearings, points, polish=polish, config=config, solver=SOLVERS[method])


# ----------------------------------------------------------------------------- Grunert / Haralick


def grunert_depths(geo):
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
    v = real_quartic_roots(np.concatenate([A4, A3, A2, A1, A0], axis=1))  # (N,4)
    u = (((amc - 1.0) * v - 2.0 * amc * cb) * v + 1.0 + amc) / (2.0 * (cg - v * ca))
    s1 = np.sqrt(b2 / (1.0 + v * v - 2.0 * v * cb))
    lam = (s1, u * s1, v * s1)
    ok = np.isfinite(v) & np.isfinite(u) & np.isfinite(s1) & (s1 > 0) & (u > 0) & (v > 0)
    return tuple(np.nan_to_num(x) for x in lam), ok


# ----------------------------------------------------------------------------- Finsterwalder


def finsterwalder_depths(geo):
    """Seed 000 sec. III-B: a real root lambda of (10) makes (8) the line pair v = m u + n (9);
    each line in (7) gives a quadratic in u; s1 from (5), s2 = u s1, s3 = v s1 (4). Of the real
    roots we take the one whose line pair is most clearly real."""
    cg, cb, ca, c2, b2, a2 = geo
    sa2, sb2, sg2 = 1.0 - ca * ca, 1.0 - cb * cb, 1.0 - cg * cg
    G = c2 * (c2 * sb2 - b2 * sg2)
    H = b2 * (b2 - a2) * sg2 + c2 * (c2 + 2.0 * a2) * sb2 + 2.0 * b2 * c2 * (-1.0 + ca * cb * cg)
    I_ = b2 * (b2 - c2) * sa2 + a2 * (a2 + 2.0 * c2) * sb2 + 2.0 * a2 * b2 * (-1.0 + ca * cb * cg)
    J = a2 * (a2 * sb2 - b2 * sa2)
    lam0 = real_cubic_roots(H / G, I_ / G, J / G).reshape(-1, 3)  # (N,3)
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


def kneip_poses(F, P):
    """Kneip et al. 2011: intermediate camera frame tau (f1, f1 x f2) and world frame eta
    (P1, P2, P3 plane); quartic in cos(theta), the angle of the eta plane about the P1-P2 axis;
    camera centre C and orientation R = N^T Q^T T in closed form (paper eqs. for C and Q).
    Returns flat candidates: R_wc (rows of 3-tuples), t_wc (3-tuple), instance index (M,)."""
    f1, f2, f3 = F
    P1, P2, P3 = P
    # the paper assumes f3 on the negative-z side of the tau frame: swap 1 <-> 2 otherwise
    swap = vdot(vcross(f1, f2), f3) > 0
    f1, f2 = (
        tuple(np.where(swap, b, a) for a, b in zip(f1, f2)),
        tuple(np.where(swap, a, b) for a, b in zip(f1, f2)),
    )
    P1, P2 = (
        tuple(np.where(swap, b, a) for a, b in zip(P1, P2)),
        tuple(np.where(swap, a, b) for a, b in zip(P1, P2)),
    )
    tx = f1
    tz = vunit(vcross(f1, f2))
    ty = vcross(tz, tx)
    f3t = (vdot(tx, f3), vdot(ty, f3), vdot(tz, f3))
    d12v = vsub(P2, P1)
    d12 = vnorm(d12v)
    nx = vscale(d12v, 1.0 / d12)
    nz = vunit(vcross(nx, vsub(P3, P1)))
    ny = vcross(nz, nx)
    p1, p2 = vdot(nx, vsub(P3, P1)), vdot(ny, vsub(P3, P1))
    cos_beta = vdot(f1, f2)
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
    cos_t = real_quartic_roots(np.concatenate([a4, a3, a2, a1, a0], axis=1))  # (N,4)
    inst, slot = np.nonzero(np.isfinite(cos_t) & (np.abs(cos_t) <= 1.0 + 1e-9))
    cos_t = np.clip(cos_t[inst, slot], -1.0, 1.0)
    q1, q2, p1, p2, dd, b = (x[inst, 0] for x in (q1, q2, p1, p2, dd, b))
    Nrows, Trows, P1 = (
        gather((nx, ny, nz), inst),
        gather((tx, ty, tz), inst),
        gather((P1,), inst)[0],
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


# ----------------------------------------------------------------------------- polynomial roots


def real_cubic_roots(b, c, d):
    """Real roots of x^3 + b x^2 + c x + d, coefficients of any (broadcastable) shape S ->
    (*S, 3), largest first, NaN where not real. Trigonometric form for three real roots,
    Cardano for one; then one Newton step."""
    b, c, d = (np.asarray(v, dtype=float)[..., None] for v in (b, c, d))
    p = c - b * b / 3.0
    q = 2.0 * b**3 / 27.0 - b * c / 3.0 + d
    disc = (q / 2.0) ** 2 + (p / 3.0) ** 3
    shift = -b / 3.0
    three = disc < 0
    m = 2.0 * np.sqrt(np.maximum(-p / 3.0, 0.0))
    phi = np.arccos(np.clip(np.where(three, 3.0 * q / (p * m), 0.0), -1.0, 1.0)) / 3.0
    sq = np.sqrt(np.maximum(disc, 0.0))
    single = np.cbrt(-q / 2.0 + sq) + np.cbrt(-q / 2.0 - sq) + shift
    cphi, sphi = np.cos(phi), np.sin(phi) * (np.sqrt(3.0) / 2.0)
    # cos(phi - 2 pi k / 3) for k = 0, 1, 2 (k = 0 is the largest)
    trig = m * np.concatenate([cphi, -0.5 * cphi + sphi, -0.5 * cphi - sphi], axis=-1) + shift
    x = np.where(three, trig, np.where(np.arange(3) == 0, single, np.nan))
    fx = ((x + b) * x + c) * x + d
    dfx = (3.0 * x + 2.0 * b) * x + c
    return x - np.where(dfx != 0, fx / dfx, 0.0)


def real_quartic_roots(coeffs):
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
    m = np.maximum(largest_real_cubic_root(p, 0.25 * p * p - r, -0.125 * q * q), 0.0)
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
