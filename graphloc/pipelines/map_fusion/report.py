"""Outputs of a map fusion run: fused map (PLY + PCD, per-point robot label), top and side PNG
renderings with both robots' trajectories (matplotlib scatter, headless), optimized trajectories
(TUM), and a JSON report (transform, guess, fitness, RMSE, ICP iterations, timings, P3P /
tracker summary, and errors against ground truth when it is known)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.pipelines.map_fusion.types import (
    CEILING,
    GROUND,
    ROBOT_NAMES,
    FusionRejected,
    FusionResult,
)
from graphloc.eval import write_tum
from graphloc.mapping.io import ROBOT_COLOURS, write_labelled_cloud
from graphloc.mapping.registration import pose_errors
from graphloc.names import out_path, written_whole
from graphloc.structured import dumps_json

MAX_PLOT_POINTS = 60_000


def transform_dict(T: np.ndarray) -> dict:
    return {
        "matrix": np.asarray(T).tolist(),
        "translation_m": np.asarray(T)[:3, 3].tolist(),
        "rpy_deg_xyz": Rotation.from_matrix(np.asarray(T)[:3, :3])
        .as_euler("xyz", degrees=True)
        .tolist(),
    }


def report_dict(result: FusionResult, truth: np.ndarray | None = None) -> dict:
    reg = result.registration
    out = {
        "status": "fused",
        "T_ground0_ceiling0": transform_dict(result.T_g0_c0),
        "initial_guess": transform_dict(result.guess),
        "registration": {
            "fitness": reg.fitness,
            "inlier_rmse_m": reg.inlier_rmse,
            "icp_iterations": reg.iterations,
            "sigma_from_information": np.sqrt(np.diag(np.linalg.inv(reg.information))).tolist(),
        },
        "graph": {
            "error_initial": result.graph_error[0],
            "error_final": result.graph_error[1],
            "p3p_factors": result.n_p3p_factors,
            "frames": int(len(result.poses[GROUND])),
        },
        "map_points": {
            ROBOT_NAMES[r]: int((result.map_labels == r).sum()) for r in (GROUND, CEILING)
        },
        "outliers_removed": result.outliers_removed,
        "timings_s": result.timings,
    }
    if result.decision is not None:
        out["registration_decision"] = result.decision.as_dict()
    if result.guess_info is not None:
        g = result.guess_info
        out["p3p"] = {
            "frames_used": g.frames.tolist(),
            "candidates_per_frame": g.n_candidates.tolist(),
            "frames_skipped": g.skipped_frames,
            "tracker_locked": g.locked,
            "last_frame_candidate_probability": g.probability,
        }
    if truth is not None:
        rot, tr = pose_errors(result.T_g0_c0, truth)
        g_rot, g_tr = pose_errors(result.guess, truth)
        out["errors_vs_truth"] = {
            "rot_deg": rot,
            "trans_m": tr,
            "guess_rot_deg": g_rot,
            "guess_trans_m": g_tr,
        }
    return out


def gravity_rotation(
    points: np.ndarray, labels: np.ndarray, max_tilt_deg: float = 30.0, seed: int = 0
) -> tuple[np.ndarray, bool]:
    """Rotation R (3,3) that makes the floor horizontal: RANSAC plane (Open3D segment_plane,
    seeded) through the ground robot's points below its first pose; if its normal is within
    max_tilt_deg of G0's z axis and it holds at least 10% of them, R is the smallest rotation
    taking that normal to +z (scipy align_vectors). Otherwise (no floor seen) the identity and
    False: the ground robot's frame is taken as gravity-aligned."""
    import open3d as o3d

    low = points[(labels == GROUND) & (points[:, 2] < 0.0)]
    if len(low) < 100:
        return np.eye(3), False
    o3d.utility.random.seed(seed)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(low))
    (a, b, c, _), inliers = cloud.segment_plane(0.03, 3, 1000)
    n = np.array([a, b, c]) * np.sign(c or 1.0)
    if len(inliers) < 0.1 * len(low) or n[2] < np.cos(np.deg2rad(max_tilt_deg)):
        return np.eye(3), False
    rot, _ = Rotation.align_vectors([[0.0, 0.0, 1.0]], [n])
    return rot.as_matrix(), True


def render(result: FusionResult, path: Path, view: str) -> Path:
    """Scatter of the fused map ('top': x-y, 'side': x-z) with both trajectories, in a
    gravity-aligned frame (`gravity_rotation`: G0 turned so the floor is horizontal)."""
    from graphloc.plots import plt  # the one place that sets the backend

    axes = {"top": (0, 1), "side": (0, 2)}[view]
    pts, lab = result.map_points, result.map_labels
    R, floor = gravity_rotation(pts, lab)
    pts = pts @ R.T
    if len(pts) > MAX_PLOT_POINTS:
        keep = np.random.default_rng(0).choice(len(pts), MAX_PLOT_POINTS, replace=False)
        pts, lab = pts[keep], lab[keep]
    if view == "top":  # draw low points first so furniture tops and walls stay visible
        order = np.argsort(pts[:, 2])
        pts, lab = pts[order], lab[order]
    fig, ax = plt.subplots(figsize=(9, 7))
    for r in (GROUND, CEILING):
        sel = lab == r
        ax.scatter(
            pts[sel, axes[0]],
            pts[sel, axes[1]],
            s=0.3,
            color=ROBOT_COLOURS[r],
            alpha=0.5,
            label=f"{ROBOT_NAMES[r]} scans ({int(sel.sum())} pts shown)",
            rasterized=True,
        )
    for r, marker in ((GROUND, "o"), (CEILING, "s")):
        xyz = result.poses[r][:, :3, 3] @ R.T
        ax.plot(
            xyz[:, axes[0]],
            xyz[:, axes[1]],
            "-" + marker,
            color="k",
            mfc=ROBOT_COLOURS[r],
            ms=5,
            lw=1.5,
            label=f"{ROBOT_NAMES[r]} trajectory",
        )
    ax.set_aspect("equal", adjustable="datalim")
    frame = "G0 levelled on the floor plane" if floor else "ground robot frame G0, taken as level"
    ax.set_xlabel(f"x [m] ({frame}, z up)")
    ax.set_ylabel(("y" if view == "top" else "z") + " [m]")
    ax.grid(alpha=0.3)
    legend = ax.legend(fontsize=8, loc="upper right")
    for handle in legend.legend_handles[:2]:
        handle.set_sizes([20.0])
    ax.set_title(f"fused ground + ceiling map, {view} view")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_outputs(
    result: FusionResult,
    out_dir,
    times: np.ndarray,
    truth: np.ndarray | None = None,
    extra: dict | None = None,
) -> dict:
    """Write everything (`extra` entries are merged into the JSON report, e.g. the input's
    provenance); returns {name: path} plus the report dict under 'report'."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    if len(result.map_points):
        for suffix in ("ply", "pcd"):
            paths[f"map_{suffix}"] = out_path(out, f"fused_map.{suffix}")
            write_labelled_cloud(paths[f"map_{suffix}"], result.map_points, result.map_labels)
        for view in ("top", "side"):
            paths[f"png_{view}"] = render(result, out_path(out, f"fused_{view}.png"), view)
    for r in (GROUND, CEILING):
        paths[f"tum_{ROBOT_NAMES[r]}"] = write_tum(
            out_path(out, f"trajectory_{ROBOT_NAMES[r]}.tum"), times, result.poses[r]
        )
    report = report_dict(result, truth)
    report["files"] = {k: str(v) for k, v in paths.items()}
    report.update(extra or {})
    paths["json"] = out_path(out, "fusion_report.json")
    with written_whole(paths["json"]) as tmp:
        tmp.write_text(dumps_json(report, indent=1))
    return {**paths, "report": report}


def write_rejection(
    exc: FusionRejected, out_dir, truth: np.ndarray | None = None, extra: dict | None = None
) -> dict:
    """ "Not fused": fusion_report.json with status, reasons, the guess and every candidate with
    its checks (and, when the truth is known, the best candidate's error); no map, no PNGs."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = {
        "status": "not_fused",
        "reasons": list(exc.decision.reasons),
        "initial_guess": transform_dict(exc.guess),
        "registration_decision": exc.decision.as_dict(),
    }
    if exc.guess_info is not None:
        g = exc.guess_info
        report["p3p"] = {
            "frames_used": g.frames.tolist(),
            "tracker_locked": g.locked,
            "last_frame_candidate_probability": g.probability,
        }
    if truth is not None:
        rot, tr = pose_errors(exc.decision.registration.transformation, truth)
        g_rot, g_tr = pose_errors(exc.guess, truth)
        report["errors_vs_truth"] = {
            "rejected_rot_deg": rot,
            "rejected_trans_m": tr,
            "guess_rot_deg": g_rot,
            "guess_trans_m": g_tr,
        }
    report.update(extra or {})
    path = out_path(out, "fusion_report.json")
    report["files"] = {"json": str(path)}
    with written_whole(path) as tmp:
        tmp.write_text(dumps_json(report, indent=1))
    return report


def summary_text(report: dict) -> str:
    """A few lines for the terminal: transform, ICP quality, the robust registration's
    calibrated 1-sigma (when it ran), error vs truth, timings, files (or, for a rejected fusion,
    "not fused" and why)."""
    if report.get("status") == "not_fused":
        n = len(report["registration_decision"]["candidates"])
        lines = [
            "not fused: " + "; ".join(report["reasons"]),
            f"{n} distinct candidate(s) tried; no fused map written",
            "wrote " + ", ".join(report["files"].values()),
        ]
        return "\n".join(lines)
    t = report["T_ground0_ceiling0"]
    lines = [
        f"T_ground0_ceiling0: translation {[round(v, 4) for v in t['translation_m']]} m, "
        f"rpy {[round(v, 3) for v in t['rpy_deg_xyz']]} deg",
        f"ICP fitness {report['registration']['fitness']:.3f}, "
        f"RMSE {report['registration']['inlier_rmse_m']:.4f} m, "
        f"{report['registration']['icp_iterations']} iterations",
    ]
    decision = report.get("registration_decision")
    if decision is not None and decision.get("sigma_rot_deg") is not None:
        lines.append(
            "1-sigma (calibrated covariance): rotation "
            f"{[round(v, 3) for v in decision['sigma_rot_deg']]} deg, translation "
            f"{[round(100 * v, 2) for v in decision['sigma_trans_m']]} cm; every check passed, "
            f"{len(decision['candidates'])} distinct candidate(s) tried"
        )
    if "errors_vs_truth" in report:
        e = report["errors_vs_truth"]
        lines.append(
            f"error vs truth: {e['rot_deg']:.4f} deg, {100 * e['trans_m']:.3f} cm "
            f"(initial guess {e['guess_rot_deg']:.2f} deg, {100 * e['guess_trans_m']:.1f} cm)"
        )
    lines.append(
        "timings [s]: " + ", ".join(f"{k} {v:.2f}" for k, v in report["timings_s"].items())
    )
    lines.append("wrote " + ", ".join(report["files"].values()))
    return "\n".join(lines)
