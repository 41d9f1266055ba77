"""The map-fusion benchmark on real geometry (issue 16, `scripts/bench_fusion.py --real`): per
overlap (about 60% and 30%, graphloc.experiments.real_views) and trial on the real indoor
fragment (tests/data/real_room), one ground + one flipped ceiling view (independent 50%
subsampling, 5 mm noise, ceiling sensor 2.5 m up with a random yaw), then the pose hint perturbed
by exactly 3 deg / 5 cm and by 10 deg / 20 cm (the hint's 1-sigma given to graphloc is that
perturbation). Methods on the same prepared clouds:
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
"""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from graphloc.executor import Executor

TRANS_OK_M = 0.05  # [m] success: translation error below this (both protocols)
REAL_OVERLAPS = (0.6, 0.3)
REAL_HINTS = ((3.0, 0.05), (10.0, 0.20))
REAL_METHODS = ("graphloc", "graphloc_before", "o3d_icp", "o3d_icp_fine", "fpfh_ransac")
REAL_ROT_OK_DEG = 1.0


def run_real_trial(job: tuple[float, int, bool]) -> list[dict]:
    """One view pair of the real fragment, both hint levels, every method (module docstring).
    With job[2] (calibration): graphloc only, with the uncalibrated covariance (scale 1, no
    floor), its tangent error and covariance kept for `fit_calibration`."""
    from dataclasses import replace

    import gtsam
    from scipy.spatial.transform import Rotation

    from graphloc.pipelines.map_fusion.fusion import fuse
    from graphloc.pipelines.map_fusion.types import FusionConfig, FusionInput, FusionRejected
    from graphloc.experiments.real_views import load_fragment, make_view_pair, perturb
    from graphloc.mapping.registration import (
        RegistrationConfig,
        global_fpfh_ransac,
        icp_from_hint,
        pose_errors,
        prepare,
    )
    from graphloc.mapping.robust_registration import polish

    overlap, seed, calibrate = job
    rng = np.random.default_rng([seed, int(round(1000 * overlap))])
    pair = make_view_pair(load_fragment(), overlap, rng)
    truth = pair.T_ground_ceiling
    cfg = RegistrationConfig()
    if calibrate:
        cfg = replace(cfg, covariance_scale=1.0, covariance_floor=(0.0, 0.0))
    source, target = prepare(pair.ceiling, cfg), prepare(pair.ground, cfg)
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
        T_floor = polish(source, target, truth, cfg)  # graphloc's last stage from the truth
        floor = dict(zip(("rot_deg", "trans_m"), pose_errors(T_floor, truth)))
        floor["bound_rot_cov_deg2"] = hessian_bound(pair.ceiling, pair.ground, truth, cfg).tolist()
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
        }
        inp = FusionInput(np.zeros(1), [pair.ground], [pair.ceiling], hint=hint, hint_sigma=sigma)
        variants = (
            (("graphloc", True),) if calibrate else (("graphloc", True), ("graphloc_before", False))
        )
        for name, robust in variants:
            fcfg = FusionConfig(
                registration=cfg, build_map=False, scan_matching=False, robust=robust
            )
            try:
                res = fuse(inp, fcfg)
                T, accepted, reasons = res.T_g0_c0, True, []
                seconds = res.timings["icp_s"] + res.timings["graph_s"]
                cov = res.decision.covariance if res.decision is not None else None
            except FusionRejected as exc:
                T, accepted, reasons = (
                    exc.decision.registration.transformation,
                    False,
                    list(exc.decision.reasons),
                )
                seconds, cov = exc.decision.seconds, None
            except ValueError as exc:  # before issue 16: ICP without correspondences raises
                T, accepted, reasons, seconds, cov = hint, False, [str(exc)], float("nan"), None
            out = dict(
                zip(("rot_deg", "trans_m"), pose_errors(T, truth)),
                seconds=seconds,
                accepted=accepted,
                reasons=reasons,
            )
            rv = Rotation.from_matrix(T[:3, :3] @ truth[:3, :3].T).as_rotvec(degrees=True)
            out["signed_error"] = [*rv.tolist(), *(T[:3, 3] - truth[:3, 3]).tolist()]
            if cov is not None:
                e = gtsam.Pose3(T).localCoordinates(gtsam.Pose3(truth))
                out["nees"] = float(e @ np.linalg.solve(cov, e))
                out["sigma_rot_deg"] = np.degrees(np.sqrt(np.diag(cov)[:3])).tolist()
                out["sigma_trans_m"] = np.sqrt(np.diag(cov)[3:]).tolist()
                if calibrate:
                    out["error_tangent"], out["covariance"] = e.tolist(), cov.tolist()
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


def hessian_bound(source: np.ndarray, target: np.ndarray, T: np.ndarray, cfg) -> np.ndarray:
    """3x3 rotation block [deg^2] of s^2 H^-1 for the point-to-plane objective of `polish` at
    T (T_target_source): source points within cfg.polish_distance of their nearest target point,
    on that point's plane (normal of its cfg.polish_max_nn nearest neighbours); H = J^T J with
    J = [(p x n)^T, n^T] (left perturbation, rotation vector in the target frame, the signed
    errors' convention), s^2 the residuals' variance."""
    import open3d as o3d

    p = source @ T[:3, :3].T + T[:3, 3]
    tgt = o3d.t.geometry.PointCloud(o3d.core.Tensor(np.asarray(target, dtype=np.float64)))
    tgt.estimate_normals(cfg.polish_max_nn)
    nns = o3d.core.nns.NearestNeighborSearch(tgt.point.positions)
    nns.knn_index()
    idx, d2 = nns.knn_search(o3d.core.Tensor(p), 1)
    idx, near = idx.numpy()[:, 0], d2.numpy()[:, 0] < cfg.polish_distance**2
    n = tgt.point.normals.numpy()[idx[near]]
    p = p[near]
    r = np.einsum("ij,ij->i", p - target[idx[near]], n)
    J = np.hstack([np.cross(p, n), n])
    cov = r.var(ddof=6) * np.linalg.inv(J.T @ J)
    return np.degrees(np.degrees(cov[:3, :3]))


def _cells(rows):
    keys = sorted(
        {(r["overlap_target"], r["hint_rot_deg"], r["hint_trans_m"]) for r in rows},
        key=lambda k: (-k[0], k[1]),
    )
    return [
        (k, [r for r in rows if (r["overlap_target"], r["hint_rot_deg"], r["hint_trans_m"]) == k])
        for k in keys
    ]


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
        draws = np.random.default_rng(0).multivariate_normal  # 200 errors per trial's bound
        bound_err = np.concatenate(
            [np.linalg.norm(draws(np.zeros(3), c, 200), axis=1) for c in covs]
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
        out[name]["targets_met"] = {
            "median_rot_le_0.1deg": g["successes"] > 0 and g["rot_deg_median_successes"] <= 0.1,
            "median_trans_le_1cm": g["successes"] > 0 and g["trans_m_median_successes"] <= 0.01,
            "faster_than_fpfh": out[name]["graphloc_vs_fpfh_time_ratio"] < 1.0,
            "no_false_accepts": g["false_accepts"] == 0,
        }
    return out


def plot_real(rows: list[dict], path: Path) -> None:
    from graphloc.plots import plt  # the one place that sets the backend

    cells = _cells(rows)
    fig, axes = plt.subplots(
        1, len(cells), figsize=(4.2 * len(cells), 4.2), sharex=True, sharey=True
    )
    for ax, ((ov, rd, tm), cell) in zip(np.atleast_1d(axes), cells):
        for i, m in enumerate(REAL_METHODS):
            rot = np.maximum([r[m]["rot_deg"] for r in cell], 1e-3)
            tr = np.maximum([r[m]["trans_m"] for r in cell], 1e-4)
            acc = np.array([r[m]["accepted"] for r in cell])
            ax.scatter(rot[acc], tr[acc], s=18, color=f"C{i}", label=m, alpha=0.8)
            ax.scatter(
                rot[~acc],
                tr[~acc],
                s=30,
                color=f"C{i}",
                marker="x",
                label=f"{m} (not fused)" if (~acc).any() else None,
            )
        ax.axvline(REAL_ROT_OK_DEG, color="r", ls="--", lw=1)
        ax.axhline(TRANS_OK_M, color="r", ls="--", lw=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"overlap {ov:.0%}, hint {rd:g} deg / {100 * tm:g} cm", fontsize=9)
        ax.set_xlabel("rotation error [deg]")
        ax.grid(True, which="both", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("translation error [m]")
    np.atleast_1d(axes)[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(
        "real fragment (TUM RGB-D fr3 office): ground + flipped ceiling view; "
        "x = returned as not fused; dashed = success bounds"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown_real(report: dict, command: str) -> str:
    summ = report["summary"]
    lines = [
        "# Map fusion on a real indoor fragment (issue 16)",
        "",
        f"Generated by `{command}` ({report['trials_per_overlap']} trials per overlap, "
        f"{report['wall_time_s']:.0f} s on {report['machine']['cpus']} CPUs, "
        f"{report['workers']} workers, on a shared machine: 1-minute load average "
        f"{report['machine']['load_avg_1m_at_start']:.1f} at the start and "
        f"{report['machine']['load_avg_1m_at_end']:.1f} at the end, so absolute times are "
        "inflated; every time ratio below compares methods within the same trials). Data: "
        "`tests/data/real_room` (TUM RGB-D fr3 office, CC BY 4.0). Protocol and methods: the "
        "docstring of `graphloc.experiments.fusion_bench_real`. Success: rotation error < 1 deg "
        "and translation < 5 cm (and, for graphloc, accepted). Cells: successes / trials; "
        "false accepts (fused but wrong) in brackets; not fused in braces.",
        "",
        "| method | " + " | ".join(summ) + " |",
        "|---|" + "---|" * len(summ),
    ]
    for m in REAL_METHODS:
        cells = []
        for s in summ.values():
            c = s[m]
            txt = f"{c['successes']}/{s['trials']} [{c['false_accepts']}]"
            if c["not_fused"]:
                txt += f" {{{c['not_fused']}}}"
            cells.append(txt)
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Median error on successes (rotation deg / translation cm) and median registration "
        "time [s] (clouds prepared once, shared; FPFH includes features and RANSAC):",
        "",
        "| method | " + " | ".join(summ) + " |",
        "|---|" + "---|" * len(summ),
    ]
    for m in REAL_METHODS:
        cells = []
        for s in summ.values():
            c = s[m]
            err = (
                f"{c['rot_deg_median_successes']:.3f} / {100 * c['trans_m_median_successes']:.2f}"
                if c["successes"]
                else "—"
            )
            t = f"{c['seconds_median']:.2f} s" if c["seconds_median"] is not None else "—"
            cells.append(f"{err}, {t}")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    lines.append(
        "| graphloc's last stage from the true pose (all trials) | "
        + " | ".join(
            f"{s['last_stage_from_truth']['rot_deg_median']:.3f} / "
            f"{100 * s['last_stage_from_truth']['trans_m_median']:.2f}"
            for s in summ.values()
        )
        + " |"
    )
    lines.append(
        "| Hessian bound of the last stage's objective at the true pose (rotation) | "
        + " | ".join(
            f"{s['last_stage_from_truth']['bound_rot_deg_median']:.3f} / —" for s in summ.values()
        )
        + " |"
    )
    lines.append(
        "| graphloc time / fpfh_ransac time (medians, same run) | "
        + " | ".join(f"{s['graphloc_vs_fpfh_time_ratio']:.2f}x" for s in summ.values())
        + " |"
    )
    lines += [
        "",
        "The last-stage row is `robust_registration.polish` (the last stage of graphloc's "
        "registration) started at the true pose: the error the estimator has at its own minimum "
        "with these scans (5 mm noise, independent 50% subsampling), which no start can beat; "
        "issue 16 asks for a median of at most 0.1 deg / 1 cm. The bound row is the median "
        "rotation error of an efficient estimator of that objective: per trial, the "
        "point-to-plane Hessian at the true pose (full-resolution ceiling points on the ground "
        "view's planes within the polish distance) with the residuals' variance, s^2 H^-1 "
        "(`hessian_bound`), 200 draws of its rotation block per trial, pooled. It treats the "
        "residuals as independent; surfaces the views sample differently make them correlated, "
        "so real estimators stay above it. Its 1-sigma (RMS over trials) against graphloc's "
        "observed spread [deg]:",
        "",
        "| cell | bound rot x / y / z | graphloc std rot x / y / z |",
        "|---|---|---|",
    ]
    for name, s in summ.items():
        b = s["last_stage_from_truth"]["bound_rot_sigma_deg_rms"]
        o = s["graphloc"].get("signed_error_std")
        obs = " / ".join(f"{v:.3f}" for v in o[:3]) if o else "—"
        lines.append(f"| {name} | " + " / ".join(f"{v:.3f}" for v in b) + f" | {obs} |")
    lines += [
        "",
        "graphloc's reported covariance against its errors (accepted results): mean NEES "
        "(6 dof) and its chi-square 95% band for that many trials:",
        "",
        "| cell | mean NEES | 95% band | in band |",
        "|---|---|---|---|",
    ]
    for name, s in summ.items():
        c = s["graphloc"]
        if "nees_mean" in c:
            lo, hi = c["nees_band_95"]
            lines.append(
                f"| {name} | {c['nees_mean']:.1f} | {lo:.2f}-{hi:.2f} | "
                f"{'yes' if c['nees_in_band'] else 'no'} |"
            )
    lines += [
        "",
        "graphloc's signed error over its successes, mean +- standard deviation "
        "(rotation "
        "vector of T_est T_true^-1 in G [deg]; translation [mm]); a mean several standard "
        "errors from zero is a bias no covariance can absorb:",
        "",
        "| cell | rot x | rot y | rot z | trans x | trans y | trans z |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, s in summ.items():
        c = s["graphloc"]
        if "signed_error_mean" in c:
            scale = [1.0] * 3 + [1000.0] * 3
            cells = [
                f"{mu * k:+.3f} +- {sd * k:.3f}" if k == 1.0 else f"{mu * k:+.2f} +- {sd * k:.2f}"
                for mu, sd, k in zip(c["signed_error_mean"], c["signed_error_std"], scale)
            ]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    cal_path = Path(__file__).resolve().parents[2] / "docs" / "results_fusion_calibration.json"
    if cal_path.is_file():
        cal = json.loads(cal_path.read_text())
        fit = cal["fit"]
        lines += [
            "",
            "The covariance is the cluster-robust sandwich scaled by "
            f"{fit['covariance_scale']:.3g} and floored by "
            f"{np.degrees(fit['floor_rot_rad']):.3g} deg / {1000 * fit['floor_trans_m']:.3g} mm "
            "(`calibrated_covariance`), fitted by maximum likelihood on "
            f"{cal['accepted_used']} accepted trials of seeds {cal['seeds'][0]}-{cal['seeds'][1]} "
            f"(`{cal['command']}`, docs/results_fusion_calibration.json); the NEES above is on "
            "this run's seeds, which the fit did not see.",
        ]
    lines += ["", f"Scatter of every trial: `{report['png']}`.", ""]
    return "\n".join(lines)


def main_real(args) -> int:
    trials = 3 if args.quick else args.trials
    jobs = [(ov, args.seed + i, False) for ov in REAL_OVERLAPS for i in range(trials)]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    start, load_start = time.perf_counter(), os.getloadavg()[0]
    with Executor(args.workers) as ex:
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
    report["command"] = command
    if args.doc:  # the doc's JSON (summary, no per-trial rows) and PNG beside it
        doc = Path(args.doc)
        report["png"] = str(doc.with_suffix(".png"))
        summary_only = {k: v for k, v in report.items() if k != "trials"}
        doc.with_suffix(".json").write_text(json.dumps(summary_only, indent=1) + "\n")
    (out / "bench_fusion_real.json").write_text(json.dumps(report, indent=1))
    plot_real(rows, Path(report["png"]))
    text = markdown_real(report, command)
    if args.doc:
        Path(args.doc).write_text(text)
    print(text)
    print(f"wrote {out / 'bench_fusion_real.json'} and {report['png']}")
    return 0
