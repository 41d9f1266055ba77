"""Lambda Twist (Persson & Nordberg, ECCV 2018), the P3P solver of graphloc.geometry.p3p: from
the cosines and squared sides of N instances (`p3p_soa.cosines_and_sides`) to up to four depth
triples, and the Gauss-Newton refinement of depth triples."""

from __future__ import annotations

import numpy as np

from graphloc.geometry.p3p_soa import largest_real_cubic_root, vcross, vdot, vscale, vunit


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
