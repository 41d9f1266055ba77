"""Bad input never crashes `geometry.p3p.solve_p3p` (issue 17). Property-based (hypothesis, bounded
examples so the file runs in a few seconds; GRAPHLOC_FUZZ_EXAMPLES=2000 for a deeper search):
whatever bearings and points it is given, it returns masked rows whose candidates reproject, or
raises ValueError -- never another exception. Plus a corpus of malformed inputs, each with the exact
reason it must give."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from graphloc.geometry.p3p import P3PConfig, solve_p3p
from benchmarks.baselines.p3p_seeds import METHODS, solve_p3p_by_name
from helpers import FAST

FLOATS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-10, 10),
    st.sampled_from([0.0, 1e-300, 1e300, -1e300]),
)


@FAST
@given(
    f=hnp.arrays(
        np.float64,
        st.tuples(st.integers(0, 3), st.integers(2, 4), st.integers(2, 4)),
        elements=FLOATS,
    ),
    X=hnp.arrays(
        np.float64,
        st.tuples(st.integers(0, 3), st.integers(2, 4), st.integers(2, 4)),
        elements=FLOATS,
    ),
    method=st.sampled_from(METHODS),
    polish=st.booleans(),
)
def test_solve_p3p_returns_masked_rows_or_raises_value_error(f, X, method, polish):
    try:
        out = solve_p3p_by_name(f, X, method=method, polish=polish)
    except ValueError as exc:
        assert f.shape[1:] != (3, 3) or X.shape != f.shape, exc
        return
    n = len(f)
    assert out.R_wc.shape == (n, 4, 3, 3) and out.valid.shape == (n, 4)
    assert np.isfinite(out.R_wc[out.valid]).all() and np.isfinite(out.t_wc[out.valid]).all()
    bad = ~(np.isfinite(f).all(axis=(1, 2)) & np.isfinite(X).all(axis=(1, 2)))
    assert not out.valid[bad].any() and out.degenerate[bad].all()


@FAST
@given(
    f=hnp.arrays(np.float64, (2, 3, 3), elements=st.floats(-1, 1)),
    X=hnp.arrays(np.float64, (2, 3, 3), elements=st.floats(-5, 5)),
)
def test_solve_p3p_candidates_reproject(f, X):
    """Whatever the geometry, every candidate returned is genuine: positive depths and the
    bearings reproduce within max_residual_rad (the contract the engines rely on)."""
    out = solve_p3p(f, X)
    for i, k in zip(*np.nonzero(out.valid)):
        d = (X[i] - out.t_wc[i, k]) @ out.R_wc[i, k]  # world points in the camera frame
        unit = d / np.linalg.norm(d, axis=1, keepdims=True)
        fi = f[i] / np.linalg.norm(f[i], axis=1, keepdims=True)
        assert np.all(np.einsum("ij,ij->i", unit, fi) > np.cos(1e-5))


P3P_CORPUS = [
    (
        lambda: solve_p3p_by_name(np.zeros((1, 3, 3)), np.zeros((1, 3, 3)), method="ransac"),
        r"solve_p3p_by_name: unknown method 'ransac'",
    ),
    (
        lambda: solve_p3p(np.zeros((3, 3)), np.zeros((3, 3))),
        r"solve_p3p: bearings must have shape \(N,3,3\), got \(3, 3\)",
    ),
    (
        lambda: solve_p3p(np.zeros((2, 3, 3)), np.zeros((1, 3, 3))),
        r"solve_p3p: points must have shape \(2, 3, 3\) like bearings, got \(1, 3, 3\)",
    ),
    (
        lambda: solve_p3p([[["a"] * 3] * 3], np.zeros((1, 3, 3))),
        r"solve_p3p: bearings/points are not numeric arrays",
    ),
    (
        lambda: solve_p3p(np.zeros((1, 3, 3), complex), np.zeros((1, 3, 3))),
        r"solve_p3p: bearings must be real numbers, got dtype complex128",
    ),
    (
        lambda: solve_p3p(
            np.zeros((1, 3, 3)), np.zeros((1, 3, 3)), config=P3PConfig(max_residual_rad=-1.0)
        ),
        r"P3PConfig.max_residual_rad must be finite and > 0, got -1.0",
    ),
    (
        lambda: solve_p3p(
            np.zeros((1, 3, 3)), np.zeros((1, 3, 3)), config=P3PConfig(polish_iters=-2)
        ),
        r"P3PConfig.polish_iters must be an integer >= 0, got -2",
    ),
]


@pytest.mark.parametrize("call, reason", P3P_CORPUS)
def test_p3p_corpus_gives_the_exact_reason(call, reason):
    with pytest.raises(ValueError, match=reason):
        call()
