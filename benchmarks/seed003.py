"""Benchmark: cooperative motion and structure on the rendered `crawler-pair` scenario
(seed 003, 003_8db27855ce2d5f68.txt, section III / Fig. 6: absolute
translation error per axis with N = 1, 2, 10, 20 feature points, N counting the robot
tracker's point, so N - 1 KLT tracks).

Every trial renders one sequence (a different random scene and motion per trial) and runs the
same front-end measurements (KLT tracks, circle candidates) through
  - ekf:    the seed's EKF (benchmarks.baselines.ekf_seed003, 'proper' tracker covariance),
  - batch:  benchmarks.cooperative_sfm through Session batch LM (final smoothed
            trajectory), the two circle candidates of each sighting as a max-mixture on the
            relative pose (factors.mixture.max_mixture_factor; centre and normal),
  - online: the same factors through Session iSAM2; each frame's estimate when it arrived
            (causal, like the filter),
  - batch_centre: baseline teammate_model 'moment_matched_centre' (batch; the candidates'
            centres merged into one Gaussian, normals unused) -- does the mixture help?
  - batch_crossings: batch with the seed's rim, the interpolated edge crossings
            (BlobConfig.refine_edges=False, their calibrated floors) -- does the edge fit help?
  - batch_crlb_circle: batch with circle candidates from a disk drawn at the Cramer-Rao bound
            of each image (`seed003_measures.disk_information`, known background: no
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

Writes OUT/bench_seed003.json, OUT/bench_seed003.md (benchmarks.render.seed003, from the
JSON), OUT/axis_errors.png, OUT/error_curves.png, OUT/scale_error.png; with --doc the markdown
there too and the JSON beside it (docs/results_seed003.{md,json}).

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

import numpy as np
from tqdm import tqdm

from benchmarks.baselines.ekf_seed003 import EkfConfig, run_ekf
from graphloc.datasets.crawler_pair import CrawlerPairConfig, CrawlerPairScenario
from benchmarks.seed003_geometry import (
    genuine_candidates,
    with_teammate_from_geometry,
)
from benchmarks.seed003_measures import (
    AXES,
    EXACT_DISK_SIGMAS,
    FRONT_ENDS,
    GRAPH_RUNS,
    METHODS,
    TRACK_AGES,
    axis_errors,
    crlb_errors,
    disk_information,
    front_end_errors,
    linearize_cost,
    scale_errors,
    teammate_config,
    track_errors,
    unseen_displacement,
)
from benchmarks.seed003_report import write_plots
from benchmarks.markdown import write_report
from benchmarks.render import render
from benchmarks.cooperative_sfm import CooperativeSfmConfig, run_cooperative_sfm
from graphloc.vision.features import FeatureConfig
from graphloc.vision.teammate import measure_frames
from graphloc.structured import dumps_json


def run_trial(seed: int, n_values: list[int], scenario: CrawlerPairConfig) -> dict:
    """One rendered sequence through every method and N; errors in metres."""
    generator = CrawlerPairScenario(replace(scenario, seed=seed))
    seq = generator.render_sequence()
    camera_moved, teammate_moved, odo, odo_std = seq.frame_flags()
    truth = seq.t_wc
    depth = seq.config.background_distance
    radius = seq.config.base_radius
    centres_cam, normals_cam = (
        np.array(a) for a in zip(*(seq.base_in_camera(k) for k in range(len(seq))))
    )
    disk_cov = np.array(
        [np.linalg.inv(disk_information(generator, seq, k, subsamples=16)) for k in range(len(seq))]
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

    def rms(k):
        return float(
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
        help="also write the doc, headed by the command that made them, to this markdown file "
        "(docs/results_seed003.md) and its JSON beside it",
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
    command = "scripts/bench_seed003.py " + " ".join(argv if argv is not None else sys.argv[1:])
    payload = {
        "command": command.strip(),
        "date": time.strftime("%Y-%m-%d"),
        "out": str(out),
        "trials": args.trials,
        "seeds": list(seeds),
        "n_values": n_values,
        "scenario": asdict(scenario),
        "time_ratio_online_over_ekf": ratio,
        "linearize_cost": cost,
        **result,
    }
    payload = json.loads(dumps_json(payload, default=str))  # as the doc's JSON reads back
    doc = Path(args.doc) if args.doc else None
    text = render("seed003", payload, doc=doc.stem if doc else "bench_seed003")
    write_report(out, "bench_seed003", payload, text, doc, rendered=payload)
    write_plots(result["per_n"], n_values, out)
    print(text)
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
