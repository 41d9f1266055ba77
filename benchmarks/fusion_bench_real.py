"""The map-fusion benchmark on real geometry (issue 16, `scripts/bench_fusion.py --real`): per
overlap (about 60% and 30%, benchmarks.real_views) and trial on a real indoor fragment
(tests/data/real_room's TUM office, or --fragment FILE), one ground + one flipped ceiling view
(independent 50% subsampling, 5 mm noise -- --keep / --noise change them to probe other
sensors --, ceiling sensor 2.5 m up with a random yaw), then the
pose hint perturbed by exactly 3 deg / 5 cm and by 10 deg / 20 cm (the hint's 1-sigma given to
graphloc is that perturbation). Methods on the same prepared clouds:
  graphloc        fuse (robust_register + acceptance checks + graph), what fuse-maps --hint runs
  graphloc_before fuse with robust=False: the coarse-to-fine refine of before issue 16
  o3d_icp         Open3D point-to-plane ICP from the hint (one scale; correspondences within
                  sigma_t + sigma_rot * median range, at least the fine distance)
  o3d_icp_fine    the same within the fine distance (RegistrationConfig.max_correspondence[-1])
  fpfh_ransac     Open3D FPFH + RANSAC (no hint), then point-to-plane ICP at the fine distance
Success: rotation error < 1 deg and translation < 5 cm and, for graphloc, accepted. A false
accept is a result returned as fused with a larger error (the Open3D paths accept everything).
NEES of graphloc's accepted results against the chi-square 95% band of their mean.

    .venv/bin/python scripts/bench_fusion.py --real --trials 20 --out out/bench_fusion_real \
        --doc docs/results_fusion_real.md
    .venv/bin/python scripts/bench_fusion.py --real --trials 20 \
        --fragment tests/data/real_room/redwood_livingroom.ply \
        --out out/bench_fusion_real_redwood --doc docs/results_fusion_real_redwood.md
"""

from __future__ import annotations

import json
import os
import platform
import time
from functools import lru_cache
from pathlib import Path

import numpy as np

from benchmarks.trials import TrialExecutor
from graphloc.mapping.acceptance import AcceptanceConfig
from graphloc.mapping.registration_index import NearestIndex
from benchmarks.fusion_report_real import (
    REAL_METHODS,
    REAL_ROT_OK_DEG,
    TRANS_OK_M,
    _cells,
    plot_real,
)
from benchmarks.render import DOCS_DIR, render
from graphloc.structured import dumps_json

REAL_OVERLAPS = (0.6, 0.3)
REAL_HINTS = ((3.0, 0.05), (10.0, 0.20))
PROTOCOL_NOISE_M, PROTOCOL_KEEP = 0.005, 0.5  # issue 16's views: 5 mm noise, 50% of the points
# the calibration's trials: every check but the sigma caps, which read the calibrated covariance
UNCAPPED = AcceptanceConfig(max_sigma_rot_deg=1e9, max_sigma_trans_m=1e9)  # beyond any sigma


def icp_from_hint(
    source,
    target,
    hint: np.ndarray,
    distance: float,
    max_iterations: int = 60,
) -> tuple[np.ndarray, float]:
    """Open3D point-to-plane ICP (legacy registration_icp, one scale) from a hint: the benchmark's
    plain-ICP peer (source, target: PreparedCloud). Returns (T_target_source, seconds)."""
    import open3d as o3d

    reg_l = o3d.pipelines.registration
    start = time.perf_counter()
    r = reg_l.registration_icp(
        source.legacy,
        target.legacy,
        distance,
        np.asarray(hint, dtype=float),
        reg_l.TransformationEstimationPointToPlane(),
        reg_l.ICPConvergenceCriteria(1e-7, 1e-7, max_iterations),
    )
    return np.asarray(r.transformation), time.perf_counter() - start


def run_real_trial(job: tuple[float, int, bool, str | None, float, float]) -> list[dict]:
    """One view pair of the real fragment, both hint levels, every method (module docstring).
    job: (overlap, seed, calibration, fragment path or None for the bundled one, per-view noise
    [m], kept fraction of the points; the protocol's are PROTOCOL_NOISE_M / PROTOCOL_KEEP). With
    calibration: graphloc only, without the sigma caps (`UNCAPPED`), its tangent error and
    uncalibrated covariance terms (`RegistrationDecision.covariance_terms`) kept for
    `fit_calibration`."""
    from dataclasses import replace

    import gtsam
    from scipy.spatial.transform import Rotation

    from graphloc.pipelines.map_fusion.fusion import fuse
    from graphloc.pipelines.map_fusion.options import FusionConfig
    from graphloc.pipelines.map_fusion.types import FusionInput, FusionRejected
    from benchmarks.real_views import load_fragment, make_view_pair, perturb
    from graphloc.mapping.registration import (
        RegistrationConfig,
        global_fpfh_ransac,
        pose_errors,
        prepare,
    )
    from graphloc.mapping.registration_stages import polish

    overlap, seed, calibrate, fragment, noise_m, keep = job
    rng = np.random.default_rng([seed, int(round(1000 * overlap))])
    pair = make_view_pair(load_fragment(fragment), overlap, rng, keep=keep, noise_m=noise_m)
    truth = pair.T_ground_ceiling
    cfg = RegistrationConfig()
    t0 = time.perf_counter()
    source, target = prepare(pair.ceiling, cfg), prepare(pair.ground, cfg)
    prep_s = time.perf_counter() - t0
    if not calibrate:  # what graphloc's preparation adds to the one every method shares
        t0 = time.perf_counter()
        prepare(pair.ceiling, cfg, inter_robot=False), prepare(pair.ground, cfg, inter_robot=False)
        prep_s -= time.perf_counter() - t0
    fine = cfg.max_correspondence[-1]
    r_med = float(np.median(np.linalg.norm(source.points, axis=1)))
    if not calibrate:
        T_glob, glob_s = global_fpfh_ransac(source, target, cfg, seed=seed)
        T_fpfh, icp_s = icp_from_hint(source, target, T_glob, fine)
        fpfh = dict(
            zip(("rot_deg", "trans_m"), pose_errors(T_fpfh, truth)),
            seconds=glob_s + icp_s,
            accepted=True,
        )
        T_floor = polish(source, target, truth, cfg).transformation  # from the truth
        floor = dict(zip(("rot_deg", "trans_m"), pose_errors(T_floor, truth)))
        bound = cramer_rao_bound(*fragment_surface(fragment), pair, noise_m, cfg.polish_distance)
        floor["bound_rot_cov_deg2"] = bound.tolist()
    rows = []
    for rot_deg, trans_m in REAL_HINTS:
        hint = perturb(truth, rot_deg, trans_m, rng)
        sigma = (float(np.deg2rad(rot_deg)), trans_m)
        row = {
            "overlap_target": overlap,
            "overlap": pair.overlap,
            "seed": seed,
            "hint_rot_deg": rot_deg,
            "hint_trans_m": trans_m,
            "points": [len(source.points), len(target.points)],
            "view_points": [len(pair.ceiling), len(pair.ground)],
            "graphloc_own_prepare_s": None if calibrate else prep_s,
        }
        inp = FusionInput(np.zeros(1), [pair.ground], [pair.ceiling], hint=hint, hint_sigma=sigma)
        variants = (
            (("graphloc", True),) if calibrate else (("graphloc", True), ("graphloc_before", False))
        )
        for name, robust in variants:
            fcfg = FusionConfig(
                registration=cfg, build_map=False, scan_matching=False, robust=robust
            )
            if calibrate:  # the caps read the calibrated covariance: no part of the selection
                fcfg = replace(fcfg, acceptance=UNCAPPED)
            try:
                res = fuse(inp, fcfg)
                T, accepted, reasons = res.T_g0_c0, True, []
                seconds = res.timings["icp_s"] + res.timings["graph_s"]
                cov = res.decision.covariance if res.decision is not None else None
                terms = res.decision.covariance_terms if res.decision is not None else None
                stages = res.decision.timings if res.decision is not None else None
            except FusionRejected as exc:
                T, accepted, reasons = (
                    exc.decision.registration.transformation,
                    False,
                    list(exc.decision.reasons),
                )
                seconds, cov, stages = exc.decision.seconds, None, exc.decision.timings
            except ValueError as exc:  # before issue 16: ICP without correspondences raises
                T, accepted, reasons, seconds, cov = hint, False, [str(exc)], float("nan"), None
                stages = None
            out = dict(
                zip(("rot_deg", "trans_m"), pose_errors(T, truth)),
                seconds=seconds,
                accepted=accepted,
                reasons=reasons,
            )
            if stages:
                out["stages"] = stages
            rv = Rotation.from_matrix(T[:3, :3] @ truth[:3, :3].T).as_rotvec(degrees=True)
            out["signed_error"] = [*rv.tolist(), *(T[:3, 3] - truth[:3, 3]).tolist()]
            if cov is not None:
                e = gtsam.Pose3(T).localCoordinates(gtsam.Pose3(truth))
                out["nees"] = float(e @ np.linalg.solve(cov, e))
                out["sigma_rot_deg"] = np.degrees(np.sqrt(np.diag(cov)[:3])).tolist()
                out["sigma_trans_m"] = np.sqrt(np.diag(cov)[3:]).tolist()
                if calibrate and terms is not None:  # None: no covariance could be computed
                    out["error_tangent"] = e.tolist()
                    out["covariance_terms"] = [np.asarray(t).tolist() for t in terms]
            row[name] = out
        if calibrate:
            rows.append(row)
            continue
        row["fpfh_ransac"] = fpfh
        row["last_stage_from_truth"] = floor
        dist = max(fine, trans_m + np.deg2rad(rot_deg) * r_med)
        T_icp, icp_s = icp_from_hint(source, target, hint, dist)
        row["o3d_icp"] = dict(
            zip(("rot_deg", "trans_m"), pose_errors(T_icp, truth)),
            seconds=icp_s,
            accepted=True,
            distance_m=dist,
        )
        T_icp, icp_s = icp_from_hint(source, target, hint, fine)
        row["o3d_icp_fine"] = dict(
            zip(("rot_deg", "trans_m"), pose_errors(T_icp, truth)),
            seconds=icp_s,
            accepted=True,
            distance_m=fine,
        )
        rows.append(row)
    return rows


@lru_cache(maxsize=4)
def fragment_surface(fragment: str | None) -> tuple[np.ndarray, np.ndarray]:
    """The real fragment's points (`load_fragment`) and the normals of their 30 nearest: the
    surface `cramer_rao_bound` takes as known, estimated once per fragment and process."""
    import open3d as o3d

    from benchmarks.real_views import load_fragment

    points = load_fragment(fragment)
    surface = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    surface.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(30))
    return points, np.asarray(surface.normals)


def cramer_rao_bound(
    surface: np.ndarray, normals: np.ndarray, pair, noise_m: float, distance: float
) -> np.ndarray:
    """3x3 rotation block [deg^2] (rotation vector in G) of the Cramer-Rao bound on
    pair.T_ground_ceiling from its two views (`benchmarks.real_views.ViewPair`, cut
    from the (N,3) `surface` points with isotropic Gaussian noise of noise_m per axis). The
    surface is taken as known -- each view point on the plane of its nearest surface point, of
    that point's (N,3) unit `normals` (`fragment_surface`) -- and only the overlap informs the
    relative pose: a view's points within `distance` of the other view at the truth. Each view's
    pose against the surface has the information I_v = sum J^T J / noise_m^2,
    J = [((p - c) x n)^T, n^T] (rotation about the overlap's centroid c, in G), and the relative
    pose the covariance I_ground^-1 + I_ceiling^-1. Any unbiased estimator that knows the
    surface errs at least this much (the two views' noise is independent; the fragment's own is
    common to both and cancels); one that must learn the surface from the views, its fine shape
    included, errs more. Zero without noise, NaN when an overlap leaves a direction
    unconstrained."""
    from scipy.spatial import cKDTree

    if noise_m <= 0:
        return np.zeros((3, 3))
    T = pair.T_ground_ceiling
    views = (np.asarray(pair.ground), pair.ceiling @ T[:3, :3].T + T[:3, 3])
    overlaps = [
        a[NearestIndex(b, distance).nearest(a)[1] < distance] for a, b in (views, views[::-1])
    ]
    c = np.vstack(overlaps).mean(axis=0)
    nearest = cKDTree(surface)
    cov = np.zeros((6, 6))
    for p in overlaps:
        n = normals[nearest.query(p)[1]]
        J = np.hstack([np.cross(p - c, n), n])
        if len(p) < 6 or np.linalg.cond(J.T @ J) > 1e12:  # the overlap leaves a direction free
            return np.full((3, 3), np.nan)
        cov += noise_m**2 * np.linalg.inv(J.T @ J)
    return np.degrees(np.degrees(cov[:3, :3]))


def summarize_real(rows: list[dict]) -> dict:
    from scipy.stats import chi2

    out = {}
    for (ov, rd, tm), cell in _cells(rows):
        name = f"overlap {ov:.0%}, hint {rd:g} deg / {100 * tm:g} cm"
        out[name] = {
            "trials": len(cell),
            "overlap_measured_median": float(np.median([r["overlap"] for r in cell])),
        }
        for m in REAL_METHODS:
            rot = np.array([r[m]["rot_deg"] for r in cell])
            tr = np.array([r[m]["trans_m"] for r in cell])
            acc = np.array([r[m]["accepted"] for r in cell])
            good = (rot < REAL_ROT_OK_DEG) & (tr < TRANS_OK_M)
            ok = good & acc
            secs = np.array([r[m]["seconds"] for r in cell], dtype=float)
            s = {
                "successes": int(ok.sum()),
                "success_rate": float(ok.mean()),
                "false_accepts": int((acc & ~good).sum()),
                "not_fused": int((~acc).sum()),
                "rot_deg_median_successes": float(np.median(rot[ok])) if ok.any() else None,
                "trans_m_median_successes": float(np.median(tr[ok])) if ok.any() else None,
                "seconds_median": float(np.nanmedian(secs)) if np.isfinite(secs).any() else None,
            }
            stages = [r[m]["stages"] for r in cell if "stages" in r[m]]
            if stages:  # graphloc: median seconds per stage, starts, fine stages, polish rounds
                s["stages_median"] = {
                    k: float(np.median([st[k] for st in stages])) for k in stages[0]
                }
            signed = np.array(
                [r[m]["signed_error"] for r, k in zip(cell, ok) if k and "signed_error" in r[m]]
            )
            if len(signed) > 1:  # rotation vector [deg], translation [m] of T_est T_true^-1 in G
                s["signed_error_mean"] = signed.mean(axis=0).tolist()
                s["signed_error_std"] = signed.std(axis=0, ddof=1).tolist()
            nees = np.array([r[m]["nees"] for r in cell if "nees" in r[m] and r[m]["accepted"]])
            if len(nees):
                lo, hi = chi2.ppf([0.025, 0.975], 6 * len(nees)) / len(nees)
                s["nees_mean"], s["nees_band_95"] = float(nees.mean()), [float(lo), float(hi)]
                s["nees_in_band"] = bool(lo <= nees.mean() <= hi)
            out[name][m] = s
        floors = [r["last_stage_from_truth"] for r in cell]
        covs = np.array([f["bound_rot_cov_deg2"] for f in floors])
        covs = covs[np.isfinite(covs).all(axis=(1, 2))]  # NaN: an overlap with a free direction
        draws = np.random.default_rng(0).multivariate_normal  # 200 errors per trial's bound
        bound_err = np.concatenate(
            [np.linalg.norm(draws(np.zeros(3), c, 200), axis=1) for c in covs] or [[np.nan]]
        )
        out[name]["last_stage_from_truth"] = {
            "rot_deg_median": float(np.median([f["rot_deg"] for f in floors])),
            "trans_m_median": float(np.median([f["trans_m"] for f in floors])),
            "bound_rot_sigma_deg_rms": np.sqrt(
                np.mean(np.diagonal(covs, axis1=1, axis2=2), 0)
            ).tolist(),
            "bound_rot_deg_median": float(np.median(bound_err)),
        }
        g, f = out[name]["graphloc"], out[name]["fpfh_ransac"]
        out[name]["graphloc_vs_fpfh_time_ratio"] = g["seconds_median"] / f["seconds_median"]
        # ... and with what graphloc's preparation adds per view pair (the scans' residual
        # spread), every trial's registration charged with it
        own = np.array([r["graphloc_own_prepare_s"] for r in cell])
        with_own = np.array([r["graphloc"]["seconds"] for r in cell]) + own
        out[name]["graphloc_own_prepare_s_median"] = float(np.median(own))
        out[name]["graphloc_with_own_prepare_vs_fpfh_time_ratio"] = float(
            np.nanmedian(with_own) / f["seconds_median"]
        )
        out[name]["targets_met"] = {
            "median_rot_le_0.1deg": g["successes"] > 0 and g["rot_deg_median_successes"] <= 0.1,
            "median_trans_le_1cm": g["successes"] > 0 and g["trans_m_median_successes"] <= 0.01,
            "faster_than_fpfh": out[name]["graphloc_vs_fpfh_time_ratio"] < 1.0,
            "no_false_accepts": g["false_accepts"] == 0,
        }
    return out


def view_options(args) -> str:
    """The command line's options for the views: --fragment when not the bundled one, and
    --noise / --keep when off issue 16's protocol (PROTOCOL_NOISE_M / PROTOCOL_KEEP)."""
    out = f" --fragment {args.fragment}" if args.fragment else ""
    if (args.noise, args.keep) != (PROTOCOL_NOISE_M, PROTOCOL_KEEP):
        out += f" --noise {args.noise:g} --keep {args.keep:g}"
    return out


def main_real(args) -> int:
    trials = 3 if args.quick else args.trials
    jobs = [
        (ov, args.seed + i, False, args.fragment, args.noise, args.keep)
        for ov in REAL_OVERLAPS
        for i in range(trials)
    ]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    start, load_start = time.perf_counter(), os.getloadavg()[0]
    with TrialExecutor(args.workers) as ex:
        rows = [r for rs in ex.imap(run_real_trial, jobs, desc="view pairs") for r in rs]
    rows.sort(key=lambda r: (-r["overlap_target"], r["hint_rot_deg"], r["seed"]))
    report = {
        "benchmark": "fusion_real",
        "trials_per_overlap": trials,
        "workers": args.workers,
        "success": {"rot_deg": REAL_ROT_OK_DEG, "trans_m": TRANS_OK_M},
        "wall_time_s": time.perf_counter() - start,
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "load_avg_1m_at_start": load_start,
            "load_avg_1m_at_end": os.getloadavg()[0],
        },
        "png": str(out / "bench_fusion_real.png"),
        "summary": summarize_real(rows),
        "trials": rows,
    }
    command = "python scripts/bench_fusion.py --real --trials %d --seed %d" % (trials, args.seed)
    command += view_options(args)
    if args.fragment:
        report["fragment"] = str(args.fragment)
    report["views"] = {"noise_m": args.noise, "keep": args.keep}
    report["command"] = command
    if args.doc:  # the doc's JSON (summary, no per-trial rows) and PNG beside it
        doc = Path(args.doc)
        report["png"] = str(doc.with_suffix(".png"))
        summary_only = {k: v for k, v in report.items() if k != "trials"}
        doc.with_suffix(".json").write_text(dumps_json(summary_only, indent=1) + "\n")
    (out / "bench_fusion_real.json").write_text(dumps_json(report, indent=1))
    plot_real(rows, Path(report["png"]), Path(args.fragment).name if args.fragment else None)
    calibration = json.loads((DOCS_DIR / "results_fusion_calibration.json").read_text())
    text = render("fusion_real", report, calibration)
    if args.doc:
        Path(args.doc).write_text(text)
    print(text)
    print(f"wrote {out / 'bench_fusion_real.json'} and {report['png']}")
    return 0
