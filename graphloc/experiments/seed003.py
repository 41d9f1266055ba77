"""Benchmark: cooperative motion and structure on the rendered `crawler-pair` scenario
(seed 003, 003_8db27855ce2d5f68.txt, section III / Fig. 6: absolute
translation error per axis with N = 1, 2, 10, 20 feature points, N counting the robot
tracker's point, so N - 1 KLT tracks).

Every trial renders one sequence (a different random scene and motion per trial) and runs the
same front-end measurements (KLT tracks, circle candidates) through
  - ekf:    the seed's EKF (graphloc.baselines.ekf_seed003, 'proper' tracker covariance),
  - batch:  graphloc.pipelines.cooperative_sfm through Session batch LM (final smoothed
            trajectory), the two circle candidates of each sighting as a max-mixture on the
            relative pose (factors.mixture.max_mixture_factor; centre and normal),
  - online: the same factors through Session iSAM2; each frame's estimate when it arrived
            (causal, like the filter),
  - batch_centre: baseline teammate_model 'moment_matched_centre' (batch; the candidates'
            centres merged into one Gaussian, normals unused) -- does the mixture help?
  - batch_crossings: batch with the seed's rim, the interpolated edge crossings
            (BlobConfig.refine_edges=False, their calibrated floors) -- does the edge fit help?
  - batch_crlb_circle: batch with circle candidates from a disk drawn at the Cramer-Rao bound
            of each image (`CrawlerPairScenario.disk_information`, known background: no
            front-end on these pixels can do better) and told that covariance, correlations
            included (`with_teammate_from_geometry`; same KLT tracks) -- what a circle front-end
            at the bound would give this graph (at N >= 10 the normals, told their true accuracy,
            then outweigh the KLT tracks, which keep the seed's 1 px: x / y get worse there, so
            read this column for the scale at N = 1, 2);
  - batch_exact_circle: the same with the exact disk, told it is exact (1 um, 1e-5 rad) --
            what is left is what the geometry does not observe (the rotation about the normal).
Front-end, per trial (no graph): the genuine circle candidate's centre error against the
truth along the line of sight (depth) and across it, its frame-to-frame change while only the
camera moves (what the scale sees), and the genuine normal's angle error, for both rims, and
the Cramer-Rao bound of the same quantities.
KLT, per trial (largest N): each track's pixel error against the true projection of the
surface point at its first pixel, by track age (drift; the graph weights tracks at 1 px).
Geometry, per trial: at the 3rd sighting, the camera's true rotation about the disk-normal axis
through the base centre since frame 0 (a circle cannot see it: the image of a circle is the
same after it) times the camera's distance from that axis -- the camera displacement that only
KLT tracks and the motion prior can tell.
Metrics per method and N: mean absolute translation error per axis over the sequence [mm]
(mean and std over trials), per-frame error curves, the trajectory scale error at each frame
(|s - 1|, s = least-squares ratio of the lengths of the camera displacements from frame 0,
using what was known at that frame) from the teammate's third sighting on, and the wall-clock
time per frame of the estimators (graph / EKF ratio measured in the same run); per sighting,
the circle candidate the max-mixture is linearized at (batch: final estimate; online: when the
frame arrived) against the genuine one (closest normal to the true disk normal), and the cost
of one max-mixture linearization against one BetweenFactorPose3 (same run).

Targets (checked, written to the JSON): graphloc batch and online below the EKF on every axis
for every N; scale error below 2 % from the teammate's third sighting on.

Writes OUT/bench_seed003.json, OUT/bench_seed003.md, OUT/axis_errors.png,
OUT/error_curves.png, OUT/scale_error.png.

    .venv/bin/python scripts/bench_seed003.py --trials 2 --out out/bench_seed003_quick
    .venv/bin/python scripts/bench_seed003.py --out out/bench_seed003          # full: 16 trials
    .venv/bin/python scripts/bench_seed003.py --seed-offset 1000 --out out/bench_seed003_heldout

(scripts/bench_seed003.py is a thin wrapper over this module.)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.baselines.ekf_seed003 import EkfConfig, run_ekf
from graphloc.datasets.crawler_pair import CrawlerPairConfig, CrawlerPairScenario
from graphloc.datasets.seed003_geometry import genuine_candidates, with_teammate_from_geometry
from graphloc.eval import axis_errors, scale_errors
from graphloc.factors.mixture import max_mixture_factor
from graphloc.keys import pose_key
from graphloc.pipelines.cooperative_sfm import CooperativeSfmConfig, run_cooperative_sfm
from graphloc.plots import plt
from graphloc.vision.circle import circle_pose_from_rim
from graphloc.vision.features import BlobConfig, FeatureConfig, detect_base_rim
from graphloc.vision.teammate import TeammateConfig, measure_frames

METHODS = (
    "ekf",
    "batch",
    "online",
    "batch_centre",
    "batch_crossings",
    "batch_crlb_circle",
    "batch_exact_circle",
)
GRAPH_RUNS = {
    "batch": ("batch", "max_mixture", "refined"),
    "online": ("online", "max_mixture", "refined"),
    "batch_centre": ("batch", "moment_matched_centre", "refined"),
    "batch_crossings": ("batch", "max_mixture", "crossings"),
    "batch_crlb_circle": ("batch", "max_mixture", "crlb"),
    "batch_exact_circle": ("batch", "max_mixture", "exact"),
}
TRACK_AGES = ((1, 3), (4, 7), (8, 11), (12, 15))  # frames since a KLT track started
EXACT_DISK_SIGMAS = np.array(
    [1e-6, 1e-6, 1e-6, 1e-5, 1e-5]
)  # 'exact' disk: centre [m], normal tilt [rad]
FRONT_ENDS = ("refined", "crossings")
METHOD_NOTE = (
    "ekf = the seed's EKF (eq. 13 state, proper covariance settings); batch / online = graphloc "
    "(Session LM / iSAM2, circle candidates as a max-mixture, refined rim); batch_centre = the "
    "candidates' centres moment-matched into one Gaussian; batch_crossings = batch on the seed's "
    "edge-crossing rim; batch_crlb_circle = batch with the circle drawn at the Cramér-Rao bound "
    "of each "
    "image (known background) and told that covariance: what a circle front-end at the bound "
    "would give; "
    "batch_exact_circle = batch with the exact circle, told it is exact. Errors are mean absolute "
    "per axis "
    "over the sequence (mean ± std over trials); "
    "the scale error at frame k is |s - 1|, s the least-squares ratio of the estimated to the true "
    "camera displacement lengths from frame 0, using only frames 0..k."
)


def teammate_config(front_end: str, radius: float) -> TeammateConfig:
    """The teammate front-end: 'refined' (default edge fit) or 'crossings' (the seed's edge
    points, with the floors calibrated for them; see TeammateConfig)."""
    if front_end == "refined":
        return TeammateConfig(radius=radius)
    return TeammateConfig(
        radius=radius,
        blob=BlobConfig(refine_edges=False),
        radius_pixel_floor=0.01,
        centre_pixel_floor=0.08,
    )


def front_end_errors(seq, front_end: str) -> dict:
    """Per frame: the genuine circle candidate's depth error (along the line of sight) and
    lateral error [m], its normal error [deg]; and the frame-to-frame depth-error changes
    over the frames where only the camera moved."""
    cfg = teammate_config(front_end, seq.config.base_radius)
    depth, lateral, normal = [], [], []
    for k in range(len(seq)):
        blob = detect_base_rim(seq.images[k], cfg.blob)
        if blob is None or blob.refine_error:
            depth.append(np.nan), lateral.append(np.nan), normal.append(np.nan)
            continue
        cands, _ = circle_pose_from_rim(seq.camera, blob.rim, cfg.radius, cfg.circle)
        centre, true_normal = seq.base_in_camera(k)
        g = int(np.argmax(cands.R[:, :, 2] @ true_normal))
        err = cands.t[g] - centre
        los = centre / np.linalg.norm(centre)
        depth.append(float(err @ los))
        lateral.append(float(np.linalg.norm(err - (err @ los) * los)))
        normal.append(
            float(np.degrees(np.arccos(np.clip(cands.R[g, :, 2] @ true_normal, -1.0, 1.0))))
        )
    camera_moved, teammate_moved, _, _ = seq.frame_flags()
    only_camera = camera_moved[1:] & ~teammate_moved[1:]
    return {
        "depth": np.array(depth),
        "lateral": np.array(lateral),
        "normal_deg": np.array(normal),
        "depth_change": np.diff(np.array(depth))[only_camera],
    }


def crlb_errors(seq, centres: np.ndarray, disk_cov: np.ndarray) -> dict:
    """The Cramer-Rao bound of the front_end_errors quantities, per frame: depth and lateral
    sigmas [m], normal angle rms [deg], and the frame-to-frame depth-change sigma over the
    frames where only the camera moved."""
    los = centres / np.linalg.norm(centres, axis=1, keepdims=True)
    depth_var = np.einsum("ki,kij,kj->k", los, disk_cov[:, :3, :3], los)
    camera_moved, teammate_moved, _, _ = seq.frame_flags()
    only_camera = camera_moved[1:] & ~teammate_moved[1:]
    return {
        "depth_sd": np.sqrt(depth_var),
        "lateral_sd": np.sqrt(np.trace(disk_cov[:, :3, :3], axis1=1, axis2=2) - depth_var),
        "normal_rms_deg": np.degrees(np.sqrt(disk_cov[:, 3, 3] + disk_cov[:, 4, 4])),
        "depth_change_sd": np.sqrt(depth_var[1:] + depth_var[:-1])[only_camera],
    }


def track_errors(seq, frames) -> tuple[np.ndarray, np.ndarray]:
    """KLT pixel error against the truth by track age: every observation of a track, the
    distance [px] to the true projection of the surface point seen at the track's first pixel,
    and its age [frames] -- (ages (M,), errors (M,)); grows with age where the track drifts."""
    first, ages, errors = {}, [], []
    for k, f in enumerate(frames):
        ids, pixels = np.asarray(f.features.ids), np.asarray(f.features.pixels, float)
        new = np.array([i not in first for i in ids.tolist()], dtype=bool)
        if new.any():
            for i, point in zip(ids[new].tolist(), seq.surface_points(k, pixels[new])):
                first[i] = (k, point)
        if (~new).any():
            k0, points = zip(*(first[i] for i in ids[~new].tolist()))
            uv, _ = seq.camera.project((np.array(points) - seq.t_wc[k]) @ seq.R_wc[k])
            ages.extend(k - np.array(k0))
            errors.extend(np.linalg.norm(uv - pixels[~new], axis=1))
    return np.array(ages, dtype=int), np.array(errors)


AXES = ("x", "y", "z")


def unseen_displacement(seq, k: int) -> float:
    """Camera displacement [m] at frame k that no circle measurement can show: the camera's
    true rotation since frame 0 about the disk-normal axis through the base centre (the image
    of a circle does not change under it) times the camera's distance from that axis."""
    normal = seq.base_normal[k] / np.linalg.norm(seq.base_normal[k])
    angle = float(gtsam.Rot3.Logmap(gtsam.Rot3(seq.R_wc[k] @ seq.R_wc[0].T)) @ normal)
    arm = seq.t_wc[k] - seq.base_centre[k]
    return abs(angle) * float(np.linalg.norm(arm - (arm @ normal) * normal))


def run_trial(seed: int, n_values: list[int], scenario: CrawlerPairConfig) -> dict:
    """One rendered sequence through every method and N; errors in metres."""
    generator = CrawlerPairScenario(replace(scenario, seed=seed))
    seq = generator.generate()
    camera_moved, teammate_moved, odo, odo_std = seq.frame_flags()
    truth = seq.t_wc
    depth = seq.config.background_distance
    radius = seq.config.base_radius
    centres_cam, normals_cam = (
        np.array(a) for a in zip(*(seq.base_in_camera(k) for k in range(len(seq))))
    )
    disk_cov = np.array(
        [np.linalg.inv(generator.disk_information(seq, k, subsamples=16)) for k in range(len(seq))]
    )
    exact_cov = np.tile(np.diag(EXACT_DISK_SIGMAS**2), (len(seq), 1, 1))
    out = {"front_end": {fe: front_end_errors(seq, fe) for fe in FRONT_ENDS}}
    out["front_end"]["crlb"] = crlb_errors(seq, centres_cam, disk_cov)
    for n in n_values:
        measured = {
            fe: measure_frames(
                seq.images,
                seq.camera,
                camera_moved,
                teammate_moved,
                odo,
                odo_std,
                FeatureConfig(max_features=n - 1),
                teammate_config(fe, seq.config.base_radius),
            )
            for fe in FRONT_ENDS
        }
        frames, report = measured["refined"]
        for name, cov in (("crlb", disk_cov), ("exact", exact_cov)):  # the same draws for every N
            measured[name] = (
                with_teammate_from_geometry(
                    frames,
                    seq.camera,
                    centres_cam,
                    normals_cam,
                    teammate_config("refined", radius),
                    cov,
                    np.random.default_rng([seed, 3]),
                ),
                report,
            )
        sightings = np.flatnonzero([f.teammate is not None for f in frames])
        third = int(sightings[2]) if len(sightings) >= 3 else len(frames)
        res = {
            "front_end": {
                "no_blob": report.no_blob,
                "circle_failed": report.circle_failed,
                "tracks_lost": report.tracks_lost,
                "max_candidate_spread_mm": 1000 * report.max_candidate_spread,
                "max_candidate_separation": report.max_candidate_separation,
            },
            "third_sighting": third,
            "track_error": track_errors(seq, frames),
        }
        t0 = time.perf_counter()
        ekf = run_ekf(
            frames,
            seq.camera,
            EkfConfig(
                feature_depth=depth, tracker_setting="proper", pixel_pitch=seq.config.pixel_pitch
            ),
        )
        t_ekf = time.perf_counter() - t0
        res["ekf"] = {
            "positions": ekf,
            "scale": scale_errors([ekf[: k + 1] for k in range(len(ekf))], truth),
            "seconds": t_ekf,
        }
        genuine = genuine_candidates(frames, np.einsum("kji,kj->ki", seq.R_wc, seq.base_normal))
        res["genuine"] = genuine
        # first-order scale floor at the 3rd sighting: two centre depths (sigma along the line of
        # sight, from the calibrated per-candidate covariance) over the true camera displacement
        depth_sd = [
            np.sqrt(f.teammate.centre @ f.teammate.candidate_covariance @ f.teammate.centre)
            / np.linalg.norm(f.teammate.centre)
            for f in frames
            if f.teammate is not None
        ]
        moved = (
            float(np.linalg.norm(truth[third] - truth[0])) if third < len(frames) else float("nan")
        )
        res["third_sighting_displacement_m"] = moved
        res["scale_floor_3rd"] = (
            float(np.hypot(depth_sd[0], depth_sd[2]) / moved)
            if len(depth_sd) >= 3
            else float("nan")
        )
        res["unseen_displacement_3rd_m"] = (
            unseen_displacement(seq, third) if third < len(frames) else float("nan")
        )
        for method, (mode, model, fe) in GRAPH_RUNS.items():
            cfg = CooperativeSfmConfig(feature_prior_depth=depth, teammate_model=model)
            cfg = replace(cfg, session=replace(cfg.session, mode=mode))
            t0 = time.perf_counter()
            run = run_cooperative_sfm(measured[fe][0], seq.camera, cfg)
            seconds = time.perf_counter() - t0
            positions = run.final_positions if mode == "batch" else run.causal_positions
            active = run.active_final if mode == "batch" else run.active_causal
            res[method] = {
                "positions": positions,
                "scale": scale_errors(run.history, truth),
                "seconds": seconds,
                "active": active,
            }
        for m in METHODS:
            res[m]["errors"] = axis_errors(res[m]["positions"], truth)
        out[n] = res
    return out


def settled_frame(scale: np.ndarray, threshold: float) -> int:
    """First frame from which the scale error stays below `threshold` (len(scale) if never)."""
    above = np.flatnonzero(~(np.nan_to_num(scale[1:], nan=np.inf) < threshold)) + 1
    return int(above[-1] + 1) if above.size else 1


def summarize(trials: list[dict], n_values: list[int]) -> dict:
    summary = {}
    for n in n_values:
        per = {}
        for m in METHODS:
            mean_axis = np.array([t[n][m]["errors"].mean(axis=0) for t in trials])  # (trials, 3)
            curves = np.array([t[n][m]["errors"] for t in trials])  # (trials, T, 3)
            scale_after = np.array(
                [np.nanmax(t[n][m]["scale"][t[n]["third_sighting"] :]) for t in trials]
            )
            scale_final = np.array([t[n][m]["scale"][-1] for t in trials])
            settled = [settled_frame(t[n][m]["scale"], 0.02) for t in trials]
            per[m] = {
                "mean_abs_error_mm": dict(zip(AXES, (1000 * mean_axis.mean(axis=0)).tolist())),
                "std_over_trials_mm": dict(zip(AXES, (1000 * mean_axis.std(axis=0)).tolist())),
                "curve_mm": (1000 * curves.mean(axis=0)).tolist(),
                "scale_error_max_after_3rd_sighting": {
                    "mean": float(scale_after.mean()),
                    "max": float(scale_after.max()),
                    "per_trial": scale_after.tolist(),
                    "trials_above_2pct": int(np.sum(scale_after >= 0.02)),
                },
                "scale_error_last_frame": {
                    "mean": float(scale_final.mean()),
                    "max": float(scale_final.max()),
                },
                "scale_below_2pct_from_frame_worst_trial": int(max(settled)),
                # frame 0 has no displacement yet: its scale error is NaN in every trial
                "scale_curve": [None]
                + np.mean([t[n][m]["scale"][1:] for t in trials], axis=0).tolist(),
                "seconds_per_sequence": float(np.mean([t[n][m]["seconds"] for t in trials])),
            }
        per["scale_evidence"] = {
            "camera_displacement_at_3rd_sighting_mm": 1000
            * float(np.mean([t[n]["third_sighting_displacement_m"] for t in trials])),
            "first_order_scale_floor_at_3rd_sighting": float(
                np.mean([t[n]["scale_floor_3rd"] for t in trials])
            ),
            "unseen_displacement_at_3rd_sighting_mm": {
                "mean": 1000 * float(np.mean([t[n]["unseen_displacement_3rd_m"] for t in trials])),
                "max": 1000 * float(np.max([t[n]["unseen_displacement_3rd_m"] for t in trials])),
            },
        }
        for m in ("batch", "online"):
            seen = [t[n]["genuine"] >= 0 for t in trials]
            hits = sum(
                int(np.sum((t[n][m]["active"] == t[n]["genuine"])[s])) for t, s in zip(trials, seen)
            )
            total = sum(int(s.sum()) for s in seen)
            per[m]["mixture"] = {
                "sightings": total,
                "genuine_active": hits,
                "fraction_genuine": hits / total if total else float("nan"),
                "active_per_trial": [t[n][m]["active"].tolist() for t in trials],
                "genuine_per_trial": [t[n]["genuine"].tolist() for t in trials],
            }
        per["front_end"] = {
            k: int(sum(t[n]["front_end"][k] for t in trials))
            for k in ("no_blob", "circle_failed", "tracks_lost")
        }
        per["front_end"].update(
            {
                k: float(max(t[n]["front_end"][k] for t in trials))
                for k in ("max_candidate_spread_mm", "max_candidate_separation")
            }
        )
        summary[n] = per
    checks = {}
    for n in n_values:
        e = summary[n]
        for m in ("batch", "online"):
            checks[f"N={n} {m} below ekf on every axis"] = all(
                e[m]["mean_abs_error_mm"][a] < e["ekf"]["mean_abs_error_mm"][a] for a in AXES
            )
            checks[
                f"N={n} {m} scale error < 2% from 3rd sighting (mean over trials of the worst "
                "frame)"
            ] = e[m]["scale_error_max_after_3rd_sighting"]["mean"] < 0.02
            checks[f"N={n} {m} scale error < 2% from 3rd sighting (worst trial)"] = (
                e[m]["scale_error_max_after_3rd_sighting"]["max"] < 0.02
            )
    front = {}
    for fe in FRONT_ENDS:
        cat = {
            k: np.concatenate([t["front_end"][fe][k] for t in trials])
            for k in ("depth", "lateral", "normal_deg", "depth_change")
        }
        front[fe] = {
            "frames": int(cat["depth"].size),
            "failed": int(np.isnan(cat["depth"]).sum()),
            "depth_error_rms_mm": 1000 * float(np.sqrt(np.nanmean(cat["depth"] ** 2))),
            "depth_error_mean_mm": 1000 * float(np.nanmean(cat["depth"])),
            "depth_change_sd_mm": 1000 * float(np.nanstd(cat["depth_change"])),
            "lateral_error_rms_mm": 1000 * float(np.sqrt(np.nanmean(cat["lateral"] ** 2))),
            "normal_error_median_deg": float(np.nanmedian(cat["normal_deg"])),
            "normal_error_max_deg": float(np.nanmax(cat["normal_deg"])),
            "normal_error_rms_deg": float(np.sqrt(np.nanmean(cat["normal_deg"] ** 2))),
        }
    rms = lambda k: float(
        np.sqrt(np.mean(np.concatenate([t["front_end"]["crlb"][k] for t in trials]) ** 2))
    )
    front["crlb"] = {
        "frames": int(sum(len(t["front_end"]["crlb"]["depth_sd"]) for t in trials)),
        "depth_sd_rms_mm": 1000 * rms("depth_sd"),
        "depth_change_sd_mm": 1000 * rms("depth_change_sd"),
        "lateral_sd_rms_mm": 1000 * rms("lateral_sd"),
        "normal_rms_deg": rms("normal_rms_deg"),
    }
    n_max = max(n_values)
    ages = np.concatenate([t[n_max]["track_error"][0] for t in trials])
    errors = np.concatenate([t[n_max]["track_error"][1] for t in trials])
    tracks = {"n": n_max, "per_age": []}
    for lo, hi in TRACK_AGES:
        e = errors[(ages >= lo) & (ages <= hi)]
        tracks["per_age"].append(
            {
                "ages": [lo, hi],
                "observations": int(e.size),
                "median_px": float(np.median(e)) if e.size else float("nan"),
                "p90_px": float(np.percentile(e, 90)) if e.size else float("nan"),
            }
        )
    return {"per_n": summary, "checks": checks, "front_end": front, "klt_track_error": tracks}


def write_plots(summary: dict, n_values: list[int], out: Path) -> None:
    colours = {
        "ekf": "tab:red",
        "batch": "tab:blue",
        "online": "tab:green",
        "batch_centre": "tab:gray",
        "batch_crossings": "tab:orange",
        "batch_crlb_circle": "tab:brown",
        "batch_exact_circle": "tab:purple",
    }
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    width = 0.8 / len(METHODS)
    for i, axis in enumerate(AXES):
        ax = axes[i]
        for j, m in enumerate(METHODS):
            vals = [summary[n][m]["mean_abs_error_mm"][axis] for n in n_values]
            errs = [summary[n][m]["std_over_trials_mm"][axis] for n in n_values]
            offset = (j - (len(METHODS) - 1) / 2) * width
            ax.bar(
                np.arange(len(n_values)) + offset, vals, width, yerr=errs, label=m, color=colours[m]
            )
        ax.set_xticks(np.arange(len(n_values)), [f"N={n}" for n in n_values])
        ax.set_yscale("log")
        ax.set_title(f"mean |T_{axis} error| [mm]")
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(out / "axis_errors.png", dpi=120)
    plt.close(fig)

    fig, axes = plt.subplots(len(n_values), 3, figsize=(13, 2.6 * len(n_values)), squeeze=False)
    for r, n in enumerate(n_values):
        for i, axis in enumerate(AXES):
            ax = axes[r, i]
            for m in METHODS:
                curve = np.array(summary[n][m]["curve_mm"])[:, i]
                ax.plot(curve, marker=".", label=m, color=colours[m])
            ax.set_yscale("log")
            ax.set_title(f"N={n}: |T_{axis} error| [mm] vs frame", fontsize=9)
    axes[0, 0].legend()
    fig.tight_layout()
    fig.savefig(out / "error_curves.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4))
    for n in n_values:
        for m, style in (
            ("batch", "-"),
            ("online", "--"),
            ("batch_crossings", ":"),
            ("batch_crlb_circle", "-."),
        ):
            curve = np.array(summary[n][m]["scale_curve"][1:], dtype=float)
            ax.plot(np.arange(1, len(curve) + 1), 100 * curve, style, label=f"{m} N={n}")
    ax.axhline(2.0, color="k", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("frame")
    ax.set_ylabel("trajectory scale error [%] (mean over trials)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(out / "scale_error.png", dpi=120)
    plt.close(fig)


def markdown(result: dict, n_values: list[int]) -> str:
    lines = [
        "| N | method | x [mm] | y [mm] | z [mm] | scale err. after 3rd sighting (mean / worst) | "
        "trials with scale err. >= 2 % after 3rd sighting | "
        "scale < 2 % from frame (worst trial) | scale err. last frame | s / sequence |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n in n_values:
        for m in METHODS:
            e = result["per_n"][n][m]
            ax = e["mean_abs_error_mm"]
            sd = e["std_over_trials_mm"]
            sc = e["scale_error_max_after_3rd_sighting"]
            lines.append(
                f"| {n} | {m} | {ax['x']:.3f} ± {sd['x']:.3f} | {ax['y']:.3f} ± {sd['y']:.3f} | "
                f"{ax['z']:.3f} ± {sd['z']:.3f} | {100 * sc['mean']:.2f} % / "
                f"{100 * sc['max']:.2f} % | "
                f"{sc['trials_above_2pct']} / {len(sc['per_trial'])} | "
                f"{e['scale_below_2pct_from_frame_worst_trial']} | "
                f"{100 * e['scale_error_last_frame']['mean']:.2f} % | "
                f"{e['seconds_per_sequence']:.3f} |"
            )
    lines.append("")
    lines.append(
        "| N | max-mixture: genuine candidate active (batch final) | (online, when the frame "
        "arrived) | "
        "camera moved at 3rd sighting | first-order scale floor there | "
        "camera displacement a circle cannot see there (mean / max) |"
    )
    lines.append("|---|---|---|---|---|---|")
    for n in n_values:
        e = result["per_n"][n]
        b, o, ev = e["batch"]["mixture"], e["online"]["mixture"], e["scale_evidence"]
        lines.append(
            f"| {n} | {b['genuine_active']} / {b['sightings']} | {o['genuine_active']} / "
            f"{o['sightings']} | "
            f"{ev['camera_displacement_at_3rd_sighting_mm']:.1f} mm | "
            f"{100 * ev['first_order_scale_floor_at_3rd_sighting']:.2f} % | "
            f"{ev['unseen_displacement_at_3rd_sighting_mm']['mean']:.2f} / "
            f"{ev['unseen_displacement_at_3rd_sighting_mm']['max']:.2f} mm |"
        )
    lines.append("")
    lines.append(
        "| teammate rim | frames (failed) | depth error rms / mean [mm] | frame-to-frame depth "
        "change sd "
        "(camera moving) [mm] | lateral error rms [mm] | genuine normal error median / max [deg] | "
        "normal error rms [deg] |"
    )
    lines.append("|---|---|---|---|---|---|---|")
    for fe in FRONT_ENDS:
        e = result["front_end"][fe]
        lines.append(
            f"| {fe} | {e['frames']} ({e['failed']}) | {e['depth_error_rms_mm']:.3f} / "
            f"{e['depth_error_mean_mm']:+.3f} | {e['depth_change_sd_mm']:.3f} | "
            f"{e['lateral_error_rms_mm']:.4f} | "
            f"{e['normal_error_median_deg']:.2f} / {e['normal_error_max_deg']:.2f} | "
            f"{e['normal_error_rms_deg']:.2f} |"
        )
    e = result["front_end"]["crlb"]
    lines.append(
        f"| Cramér-Rao bound (known background) | {e['frames']} | {e['depth_sd_rms_mm']:.3f} "
        "(sigma) | "
        f"{e['depth_change_sd_mm']:.3f} | {e['lateral_sd_rms_mm']:.4f} | - | "
        f"{e['normal_rms_deg']:.2f} |"
    )
    lines.append("")
    t = result["klt_track_error"]
    lines.append(
        f"| KLT track age [frames] (N = {t['n']}) | observations | error vs the true projection "
        "of the "
        "track's first point, median / p90 [px] |"
    )
    lines.append("|---|---|---|")
    for row in t["per_age"]:
        lines.append(
            f"| {row['ages'][0]}-{row['ages'][1]} | {row['observations']} | "
            f"{row['median_px']:.3f} / "
            f"{row['p90_px']:.3f} |"
        )
    lines.append("")
    for k, v in result["checks"].items():
        lines.append(f"- {'PASS' if v else 'FAIL'}: {k}")
    return "\n".join(lines) + "\n"


def linearize_cost(repeats: int = 3000) -> dict:
    """Seconds per linearization of a 2-component max-mixture of BetweenFactorPose3 (a Python
    CustomFactor) and of one BetweenFactorPose3 (C++), measured in the same run."""
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.015, 0.015, 1.0, 2e-4, 2e-4, 5e-4]))
    a, b = pose_key(0, 0), pose_key(1, 0)
    poses = [gtsam.Pose3(gtsam.Rot3.Ry(s), [0.03, 0.03, 0.83]) for s in (0.2, -0.15)]
    between = gtsam.BetweenFactorPose3(a, b, poses[0], noise)
    mixture = max_mixture_factor(
        [gtsam.BetweenFactorPose3(a, b, p, noise) for p in poses], [0.5, 0.5]
    ).factor
    values = gtsam.Values()
    values.insert(a, gtsam.Pose3())
    values.insert(b, gtsam.Pose3(gtsam.Rot3.Ry(0.19), [0.031, 0.03, 0.829]))
    out = {}
    for name, factor in (("between_pose3", between), ("max_mixture_2", mixture)):
        factor.linearize(values)
        t0 = time.perf_counter()
        for _ in range(repeats):
            factor.linearize(values)
        out[f"{name}_us"] = 1e6 * (time.perf_counter() - t0) / repeats
    out["ratio_max_mixture_over_between"] = out["max_mixture_2_us"] / out["between_pose3_us"]
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--trials", type=int, default=16, help="rendered sequences (seeds offset..offset+trials-1)"
    )
    parser.add_argument(
        "--seed-offset", type=int, default=0, help="first scenario seed (held-out runs: e.g. 1000)"
    )
    parser.add_argument(
        "--n-features", default="1,2,10,20", help="N values (tracker point + N-1 KLT tracks)"
    )
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--out", default="out/bench_seed003")
    parser.add_argument(
        "--doc",
        default=None,
        help="also write the tables, headed by the command that made them, to this markdown file "
        "(docs/results_seed003.md)",
    )
    args = parser.parse_args(argv)
    n_values = [int(v) for v in args.n_features.split(",")]
    if any(n < 1 for n in n_values) or args.trials < 1:
        parser.error("--n-features values must be >= 1 and --trials >= 1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scenario = CrawlerPairConfig(width=args.width, height=args.height)
    seeds = range(args.seed_offset, args.seed_offset + args.trials)
    trials = [run_trial(seed, n_values, scenario) for seed in tqdm(seeds, desc="seed-003 trials")]
    result = summarize(trials, n_values)
    ratio = {
        n: result["per_n"][n]["online"]["seconds_per_sequence"]
        / result["per_n"][n]["ekf"]["seconds_per_sequence"]
        for n in n_values
    }
    cost = linearize_cost()
    payload = {
        "trials": args.trials,
        "seeds": list(seeds),
        "n_values": n_values,
        "scenario": asdict(scenario),
        "time_ratio_online_over_ekf": ratio,
        "linearize_cost": cost,
        **result,
    }
    (out / "bench_seed003.json").write_text(json.dumps(payload, indent=1, default=str))
    (out / "bench_seed003.md").write_text(markdown(result, n_values))
    write_plots(result["per_n"], n_values, out)
    if args.doc:
        command = "scripts/bench_seed003.py " + " ".join(argv if argv is not None else sys.argv[1:])
        header = (
            "# Seed 003 on crawler-pair: EKF vs graphloc\n\nGenerated by `.venv/bin/python "
            f"{command.strip()}` "
            f"(seeds {seeds.start}-{seeds.stop - 1}, {time.strftime('%Y-%m-%d')}); the JSON and "
            "PNG plots go to "
            f"`{out}/`. Columns: {METHOD_NOTE}\n\n"
        )
        Path(args.doc).write_text(header + markdown(result, n_values))
    print(markdown(result, n_values))
    print(
        f"linearization: BetweenFactorPose3 {cost['between_pose3_us']:.1f} us, max-mixture (2 "
        "components) "
        f"{cost['max_mixture_2_us']:.1f} us, ratio {cost['ratio_max_mixture_over_between']:.1f}"
    )
    print(
        f"wrote {out}/bench_seed003.json, .md, axis_errors.png, error_curves.png, scale_error.png"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
