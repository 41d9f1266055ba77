"""The four P3P solver families of graphloc.geometry.p3p, each from the cosines and squared
sides of N instances (`p3p_soa.cosines_and_sides`) to up to four depth triples (Kneip: poses);
the references are in graphloc.geometry.p3p's docstring."""

from __future__ import annotations

import numpy as np

from graphloc.geometry.p3p_soa import (
    gather,
    largest_real_cubic_root,
    real_cubic_roots,
    real_quartic_roots,
    vcross,
    vdot,
    vnorm,
    vscale,
    vsub,
    vunit,
)


# ----------------------------------------------------------------------------- lambdatwist


def lambdatwist_depths(geo):
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
    g = largest_real_cubic_root(
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
    e2 = vcross(e0, e1)
    ratio = np.sqrt(np.maximum(-s2 / s1, 0.0))
    indefinite = pm < 0
    asum = a12 + a13 + a23
    D1e0, D1e1, D1e2 = _sym_apply(D1, e0), _sym_apply(D1, e1), _sym_apply(D1, e2)
    q00 = vdot(e0, D1e0)
    lams, oks = [], []
    for sign in (1.0, -1.0):
        # D0 = s1 e1e1' + s2 e2e2': plane (e1 - sign*ratio*e2).l = 0 is spanned by e0 and v;
        # on it l = a e0 + b v and l' D1 l = q00 a^2 + 2 q01 a b + q11 b^2 = 0
        w = sign * ratio
        v = tuple(w * a + b for a, b in zip(e1, e2))
        q01 = vdot(v, D1e0)
        q11 = vdot(v, tuple(w * a + b for a, b in zip(D1e1, D1e2)))
        disc = q01 * q01 - q00 * q11
        k = -(q01 + np.copysign(np.sqrt(np.maximum(disc, 0.0)), q01))
        for alpha, beta in ((q11, k), (k, q00)):  # the two roots, in the cancellation-free form
            d = tuple(alpha * a + beta * b for a, b in zip(e0, v))
            # scale so that sum_ij |l_i f_i - l_j f_j|^2 = a12 + a13 + a23, with sum(l) > 0
            norm2 = 2.0 * (vdot(d, d) - c12 * d[0] * d[1] - c13 * d[0] * d[2] - c23 * d[1] * d[2])
            s = np.copysign(np.sqrt(asum / norm2), d[0] + d[1] + d[2])
            lam = vscale(d, s)
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
    x01, x02, x12 = vcross(r0, r1), vcross(r0, r2), vcross(r1, r2)
    n01, n02, n12 = vdot(x01, x01), vdot(x02, x02), vdot(x12, x12)
    use01 = (n01 >= n02) & (n01 >= n12)
    use02 = ~use01 & (n02 >= n12)
    return vunit(tuple(np.where(use01, p, np.where(use02, q, r)) for p, q, r in zip(x01, x02, x12)))


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
    return vunit(col)


def _sym_apply(A, v):
    """A @ v for symmetric A (6-entry form)."""
    a, b, c, d, e, f = A
    return (
        a * v[0] + b * v[1] + c * v[2],
        b * v[0] + d * v[1] + e * v[2],
        c * v[0] + e * v[1] + f * v[2],
    )


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


def kneip(F, P):
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


# --------------------------------------------------------------- shared by the depth solvers


def refine_depths(geo, lam, iters):
    """Gauss-Newton on l_i^2 + l_j^2 - 2 c_ij l_i l_j = a_ij (3 equations, 3 unknowns) for every
    candidate (geo: `cosines_and_sides` per candidate); the Jacobian
    [[a, b, 0], [c, 0, d], [0, e, g]] is solved by its adjugate."""
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
