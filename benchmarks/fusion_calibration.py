"""`scripts/bench_fusion.py --real --calibrate` (issue 16) fits the calibration of graphloc's
registration covariance (its scale and degeneracy term,
`graphloc.mapping.registration_covariance.calibrated_covariance`) by maximum likelihood on view
pairs of both bundled real fragments, of other seeds than the benchmark's, and writes
docs/results_fusion_calibration.json (RegistrationConfig's defaults are that fit;
tests/mapping/test_fusion_real.py checks they agree):

    .venv/bin/python scripts/bench_fusion.py --real --calibrate --trials 40 --seed 1000
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.optimize import brentq, minimize_scalar
from scipy.stats import chi2

from benchmarks.trials import TrialExecutor

from benchmarks.real_views import BUNDLED_FRAGMENTS
from benchmarks.fusion_bench_real import (
    REAL_OVERLAPS,
    _cells,
    run_real_trial,
    view_options,
)
from graphloc.structured import dumps_json


def fit_calibration(errors: np.ndarray, P: np.ndarray, Q: np.ndarray) -> dict:
    """Maximum likelihood of e_i ~ N(0, s (P_i + c Q_i)) over n accepted trials
    (`graphloc.mapping.registration_covariance.calibrated_covariance`): for each c the scale in
    closed form, s = sum_i e_i^T (P_i + c Q_i)^-1 e_i / (6 n), the mean NEES over the
    dimension; c >= 0 by a bounded search of the profile likelihood. Returns both with their
    approximate 95% intervals -- s's from its chi-square distribution (6 n dof) at the fitted
    c, c's where the profile's -2 log-likelihood ("nll", up to a constant) rises by 3.84 --
    and the fit of c = 0 (the sandwich scaled alone) for comparison."""
    errors, P, Q = (np.asarray(a, dtype=float) for a in (errors, P, Q))
    n = len(errors)
    if errors.ndim != 2 or errors.shape[1] != 6 or not P.shape == Q.shape == (n, 6, 6):
        raise ValueError(
            f"fit_calibration: errors (n,6) and terms P, Q (n,6,6) expected, got {errors.shape}, "
            f"{P.shape} and {Q.shape}"
        )
    if n == 0:
        raise ValueError("fit_calibration: no accepted trial to fit")
    dof = 6 * n

    def profile(c: float):
        cov = P + c * Q
        q = nees(errors, cov)
        s = float(q.sum() / dof)
        return float(np.linalg.slogdet(s * cov)[1].sum() + q.sum() / s), s, q.sum()

    hi_c = 1e3
    c = float(minimize_scalar(lambda x: profile(x)[0], bounds=(0.0, hi_c), method="bounded").x)
    alone = profile(0.0)  # the sandwich scaled alone
    if alone[0] <= profile(c)[0]:
        c = 0.0
    nll, s, qsum = profile(c)

    def rise(x: float) -> float:  # the profile above its minimum, less the 95% threshold
        return profile(x)[0] - nll - chi2.ppf(0.95, 1)

    def edge(a: float, b: float) -> float:  # where the profile crosses it in [a, b], else b
        return brentq(rise, min(a, b), max(a, b)) if rise(a) * rise(b) < 0 else b

    lo_s, hi_s = qsum / chi2.ppf([0.975, 0.025], dof)
    return {
        "covariance_scale": s,
        "covariance_scale_95": [float(lo_s), float(hi_s)],
        "covariance_degeneracy": c,
        "covariance_degeneracy_95": [float(edge(c, 0.0)), float(edge(c, hi_c))],
        "nll": nll,
        "scale_alone": {"covariance_scale": alone[1], "nll": alone[0]},
    }


def nees(errors: np.ndarray, covs: np.ndarray) -> np.ndarray:
    """e_i^T C_i^-1 e_i for (n,6) errors and (n,6,6) covariances."""
    return np.einsum("ni,ni->n", errors, np.linalg.solve(covs, errors[..., None])[..., 0])


def main_calibrate(args) -> int:
    """`--real --calibrate`: fit the registration covariance's calibration (`fit_calibration`) on
    view pairs of seeds args.seed.. (keep them apart from the benchmark's) of both bundled
    fragments (`BUNDLED_FRAGMENTS`: the TUM office's views constrain every direction, the Redwood
    living room's 30% views hardly constrain some -- the two terms need both), or of
    --fragment alone; write the JSON and a PNG of the NEES per trial before / after."""

    from graphloc.plots import plt  # the one place that sets the backend

    fragments = [args.fragment] if args.fragment else list(BUNDLED_FRAGMENTS)
    jobs = [
        (ov, args.seed + i, True, fragment, args.noise, args.keep)
        for fragment in fragments
        for ov in REAL_OVERLAPS
        for i in range(args.trials)
    ]
    start = time.perf_counter()
    rows = []
    with TrialExecutor(args.workers) as ex:
        for job, rs in zip(jobs, ex.imap(run_real_trial, jobs, desc="calibration pairs")):
            rows += [dict(r, fragment=Path(job[3]).name) for r in rs]
    used = [r for r in rows if r["graphloc"]["accepted"] and "covariance_terms" in r["graphloc"]]
    errors = np.array([r["graphloc"]["error_tangent"] for r in used])
    P, Q = (np.array([r["graphloc"]["covariance_terms"][k] for r in used]) for k in (0, 1))
    fit = fit_calibration(errors, P, Q)
    before = nees(errors, fit["scale_alone"]["covariance_scale"] * P)
    after = nees(errors, fit["covariance_scale"] * (P + fit["covariance_degeneracy"] * Q))
    cells = {}
    for fragment in dict.fromkeys(r["fragment"] for r in used):
        for (ov, rd, tm), cell in _cells([r for r in used if r["fragment"] == fragment]):
            idx = [used.index(r) for r in cell]
            lo, hi = chi2.ppf([0.025, 0.975], 6 * len(idx)) / len(idx)
            cells[f"{fragment}: overlap {ov:.0%}, hint {rd:g} deg / {100 * tm:g} cm"] = {
                "trials": len(idx),
                "nees_mean_scale_alone": float(before[idx].mean()),
                "nees_mean_calibrated": float(after[idx].mean()),
                "nees_band_95": [float(lo), float(hi)],
            }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    png = out / "bench_fusion_calibration.png"
    fig, ax = plt.subplots(figsize=(6.5, 4))
    bins = np.logspace(-1, np.log10(max(before.max(), after.max()) * 1.1), 40)
    ax.hist(before, bins=bins, alpha=0.6, label="the sandwich scaled alone (c = 0)")
    ax.hist(after, bins=bins, alpha=0.6, label="calibrated (scale and degeneracy term)")
    ax.axvline(6.0, color="k", ls="--", lw=1, label="dimension (6)")
    ax.set_xscale("log")
    ax.set_xlabel("NEES per accepted calibration trial")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
    report = {
        "benchmark": "fusion_covariance_calibration",
        "command": f"python scripts/bench_fusion.py --real --calibrate --trials {args.trials} "
        f"--seed {args.seed}" + view_options(args),
        "views": {"noise_m": args.noise, "keep": args.keep},
        "fragments": [Path(f).name for f in fragments],
        "seeds": [args.seed, args.seed + args.trials - 1],
        "trials_per_overlap": args.trials,
        "accepted_used": len(used),
        "fit": fit,
        "cells": cells,
        "wall_time_s": time.perf_counter() - start,
        "png": str(png),
    }
    path = Path(args.calibration_json)
    path.write_text(dumps_json(report, indent=1) + "\n")
    print(dumps_json({k: report[k] for k in ("fit", "cells")}, indent=1))
    print(f"wrote {path} and {png}")
    return 0
