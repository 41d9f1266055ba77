"""Structure-of-arrays algebra of the batched P3P solvers (graphloc.geometry.p3p): vectors as
tuples of three (N,1) or (M,) arrays so that numpy does one pass per scalar operation over all
instances, the cosines and squared sides every solver starts from, and the real roots of the
cubics and quartics they reduce to."""

from __future__ import annotations

import numpy as np


def soa(A):
    """(N,3,3) rows of vectors -> tuple of 3 vectors, each a tuple of 3 contiguous (N,1) arrays."""
    T = np.ascontiguousarray(A.transpose(1, 2, 0))[..., None]
    return tuple((T[p, 0], T[p, 1], T[p, 2]) for p in range(3))


def vdot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def vcross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def vsub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def vscale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


def vnorm(a):
    return np.sqrt(vdot(a, a))


def vunit(a):
    return vscale(a, 1.0 / vnorm(a))


def cosines_and_sides(F, P):
    """Cosines between bearings and squared side lengths c12, c13, c23, a12, a13, a23 ((N,1)
    each)."""
    d12, d13, d23 = vsub(P[0], P[1]), vsub(P[0], P[2]), vsub(P[1], P[2])
    return (
        vdot(F[0], F[1]),
        vdot(F[0], F[2]),
        vdot(F[1], F[2]),
        vdot(d12, d12),
        vdot(d13, d13),
        vdot(d23, d23),
    )


def gather(V, inst):
    """Per-instance SoA vectors ((N,1) entries) -> per-candidate flat (M,) entries."""
    return tuple(tuple(x[inst, 0] for x in v) for v in V)


# ----------------------------------------------------------------------------- polynomial roots


def real_cubic_roots(b, c, d, newton_steps: int = 1, largest_only: bool = False):
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


def largest_real_cubic_root(b, c, d):
    """Largest real root (shape of the coefficients) of x^3 + b x^2 + c x + d; two Newton steps."""
    return real_cubic_roots(b, c, d, newton_steps=2, largest_only=True)


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
