"""`scripts/bench_fusion.py --real --calibrate` (issue 16) fits the calibration of graphloc's
registration covariance (its scale,
`graphloc.mapping.registration_covariance.calibrated_covariance`) by maximum likelihood on view
pairs of other seeds than the benchmark's, and writes docs/results_fusion_calibration.json
(RegistrationConfig's defaults are that fit; tests/test_fusion_real.py checks they agree):

    .venv/bin/python scripts/bench_fusion.py --real --calibrate --trials 20 --seed 1000
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from graphloc.executor import Executor

from graphloc.experiments.fusion_bench_real import (
    REAL_OVERLAPS,
    _cells,
    run_real_trial,
    view_options,
)


def fit_calibration(errors: np.ndarray, covs: np.ndarray) -> dict:
    """Maximum likelihood of e_i ~ N(0, s P_i) over n accepted trials
    (`graphloc.mapping.registration_covariance.calibrated_covariance`): in closed form,
    s = sum_i e_i^T P_i^-1 e_i / (6 n), the mean uncalibrated NEES over the dimension; with the
    approximate 95% interval of s from its chi-square distribution (6 n dof)."""
    errors, covs = np.asarray(errors, dtype=float), np.asarray(covs, dtype=float)
    if errors.ndim != 2 or errors.shape[1] != 6 or covs.shape != (len(errors), 6, 6):
        raise ValueError(
            f"fit_calibration: errors (n,6) and covariances (n,6,6) expected, got {errors.shape} "
            f"and {covs.shape}"
        )
    if len(errors) == 0:
        raise ValueError("fit_calibration: no accepted trial to fit")
    q = np.einsum("ni,ni->n", errors, np.linalg.solve(covs, errors[..., None])[..., 0])
    dof = 6 * len(q)
    s = float(q.sum() / dof)
    _, logdet = np.linalg.slogdet(s * covs)
    lo, hi = q.sum() / chi2.ppf([0.975, 0.025], dof)
    return {
        "covariance_scale": s,
        "covariance_scale_95": [float(lo), float(hi)],
        "nll": float(logdet.sum() + q.sum() / s),
    }


def main_calibrate(args) -> int:
    """`--real --calibrate`: fit the registration covariance's calibration (`fit_calibration`) on
    view pairs of seeds args.seed.. (keep them apart from the benchmark's), write the JSON and
    a PNG of the NEES per trial before / after."""

    from graphloc.plots import plt  # the one place that sets the backend

    jobs = [
        (ov, args.seed + i, True, args.fragment, args.noise, args.keep)
        for ov in REAL_OVERLAPS
        for i in range(args.trials)
    ]
    start = time.perf_counter()
    with Executor(args.workers) as ex:
        rows = [r for rs in ex.imap(run_real_trial, jobs, desc="calibration pairs") for r in rs]
    used = [r for r in rows if r["graphloc"]["accepted"] and "covariance" in r["graphloc"]]
    errors = np.array([r["graphloc"]["error_tangent"] for r in used])
    covs = np.array([r["graphloc"]["covariance"] for r in used])
    fit = fit_calibration(errors, covs)
    P = fit["covariance_scale"] * covs
    before = np.einsum("ni,ni->n", errors, np.linalg.solve(covs, errors[..., None])[..., 0])
    after = np.einsum("ni,ni->n", errors, np.linalg.solve(P, errors[..., None])[..., 0])
    cells = {}
    for (ov, rd, tm), cell in _cells(used):
        idx = [used.index(r) for r in cell]
        lo, hi = chi2.ppf([0.025, 0.975], 6 * len(idx)) / len(idx)
        cells[f"overlap {ov:.0%}, hint {rd:g} deg / {100 * tm:g} cm"] = {
            "trials": len(idx),
            "nees_mean_uncalibrated": float(before[idx].mean()),
            "nees_mean_calibrated": float(after[idx].mean()),
            "nees_band_95": [float(lo), float(hi)],
        }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    png = out / "bench_fusion_calibration.png"
    fig, ax = plt.subplots(figsize=(6.5, 4))
    bins = np.logspace(-1, np.log10(max(before.max(), after.max()) * 1.1), 40)
    ax.hist(before, bins=bins, alpha=0.6, label="cluster-robust covariance (uncalibrated)")
    ax.hist(after, bins=bins, alpha=0.6, label="calibrated (fitted scale)")
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
        "seeds": [args.seed, args.seed + args.trials - 1],
        "trials_per_overlap": args.trials,
        "accepted_used": len(used),
        "fit": fit,
        "cells": cells,
        "wall_time_s": time.perf_counter() - start,
        "png": str(png),
    }
    path = Path(args.calibration_json)
    path.write_text(json.dumps(report, indent=1) + "\n")
    print(json.dumps({k: report[k] for k in ("fit", "cells")}, indent=1))
    print(f"wrote {path} and {png}")
    return 0
