"""Structure-of-arrays algebra of the batched P3P solvers (graphloc.geometry.p3p): vectors as
tuples of three (N,1) or (M,) arrays so that numpy does one pass per scalar operation over all
instances, the cosines and squared sides every solver starts from, and the largest real root of
a cubic."""

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


def largest_real_cubic_root(b, c, d):
    """Largest real root (shape of the coefficients) of x^3 + b x^2 + c x + d: trigonometric
    form for three real roots, Cardano for one; then two Newton steps."""
    b, c, d = (np.asarray(v, dtype=float) for v in (b, c, d))
    p = c - b * b / 3.0
    q = 2.0 * b**3 / 27.0 - b * c / 3.0 + d
    disc = (q / 2.0) ** 2 + (p / 3.0) ** 3
    shift = -b / 3.0
    three = disc < 0
    m = 2.0 * np.sqrt(np.maximum(-p / 3.0, 0.0))
    phi = np.arccos(np.clip(np.where(three, 3.0 * q / (p * m), 0.0), -1.0, 1.0)) / 3.0
    sq = np.sqrt(np.maximum(disc, 0.0))
    single = np.cbrt(-q / 2.0 + sq) + np.cbrt(-q / 2.0 - sq) + shift
    x = np.where(three, m * np.cos(phi) + shift, single)
    for _ in range(2):
        fx = ((x + b) * x + c) * x + d
        dfx = (3.0 * x + 2.0 * b) * x + c
        x = x - np.where(dfx != 0, fx / dfx, 0.0)
    return x
