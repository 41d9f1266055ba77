"""Issue 20 for seed 003 (003_8db27855ce2d5f68.txt Sec. III, Fig. 6): under which reading of
the experiment does the seed's own EKF (benchmarks.baselines.ekf_seed003) show what the paper
reports for it?

What the paper reports. Fig. 6 plots the absolute error of T_x and T_z for N = 1, 2, 10, 20
feature points; its values are not in the text (the figure survives only as axis ticks
without a unit), so no number of Fig. 6 can be matched within 10 %. What the text does state:
(a) "for T_x, small N values give better estimation results", (b) "for Z, the estimation error
tends to improve as N increases", and the robot tracker's errors of Fig. 3 that feed the EKF:
"in the range of 2 cm, 0.8 cm and 9 cm" in X, Y and Z (read as the largest absolute error over
the sequence).

What the text leaves open, swept (the rendered crawler-pair scene of
graphloc.datasets.crawler_pair keeps the stated geometry: robot diameter 3.8 cm at 83 cm,
background at 260 cm):
- the tracker's error: our rendered front-end (refined rim), or a tracker whose camera-frame
  centre errors are Gaussian with per-axis std `tracker_scale` x FIG3_RANGE_CM / 2 (and a disk
  tilt std of tracker_scale x TILT_DEG) -- benchmarks.seed003_geometry
  .with_teammate_from_geometry, the same draws for every N;
- the EKF's tracker measurement noise "set to 3": a variance [px^2] or a std [px] (9 px^2);
- the KLT points' "high" initial uncertainty: 1 m or 10 m std;
- the sequence: "12 frames" with the tracked robot stationary (11 camera steps), or the
  move-and-stop schedule of the crawler-pair benchmark (16 frames, the teammate moves 3 steps).
(a) and (b) are read as trends: the sign of the least-squares slope of the error against
log N (the strict readings, every N = 1, 2 below every N = 10, 20 and T_z falling at every
step, are reported beside). A reading reproduces when (a) and (b) hold on the mean over
trials and the tracker's largest errors are within 10 % of Fig. 3's on every axis. After the
coarse grid, the chosen reading's per-axis tracker stds are fitted to Fig. 3 (`refine`; the
draws are fixed, so the fit is exact) and the claims checked there. graphloc
(benchmarks.cooperative_sfm, batch) runs on the same frames at the stated and the
chosen reading.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np

from benchmarks.baselines.ekf_seed003 import EkfConfig, run_ekf
from graphloc.datasets.crawler_pair import CrawlerPairConfig, CrawlerPairScenario
from benchmarks.seed003_geometry import genuine_candidates, with_teammate_from_geometry
from benchmarks.trials import TrialExecutor
from benchmarks.seed003_measures import teammate_config
from benchmarks.cooperative_sfm import CooperativeSfmConfig, run_cooperative_sfm
from graphloc.vision.features import FeatureConfig
from graphloc.vision.teammate import measure_frames

N_VALUES = (1, 2, 10, 20)
FIG3_RANGE_CM = np.array([2.0, 0.8, 9.0])  # Sec. III: tracker errors in X, Y, Z
TILT_DEG = 5.0  # disk tilt std of the injected tracker at scale 1 (the text gives none)
TRACKER_SCALES = (0.0, 0.5, 0.75, 1.0, 1.1, 1.25, 1.5)  # 0: our rendered front-end
TRACKER_VARIANCES = (3.0, 9.0)  # "set to 3": px^2, or 3 px std
FEATURE_SIGMAS = (1.0, 10.0)  # [m]
REFINE_ROUNDS = 2
SCHEDULES = {
    "12 frames, teammate still": ("camera",) * 11,
    "crawler-pair benchmark (16 frames)": CrawlerPairConfig().schedule,
}
STATED = {
    "tracker_scale": 0.0,
    "tracker_sd_cm": None,
    "tracker_variance": 3.0,
    "feature_sigma": 1.0,
    "schedule": "12 frames, teammate still",
}


def _measure(job) -> dict:
    """One rendered sequence of a schedule through the front-end for every N (the slow part:
    rendering and KLT); the frames, the truth and the disk in the camera frame."""
    schedule, seed = job
    gen = CrawlerPairScenario(replace(CrawlerPairConfig(), schedule=SCHEDULES[schedule], seed=seed))
    seq = gen.render_sequence()
    moved, t_moved, odo, odo_std = seq.frame_flags()
    radius = seq.config.base_radius
    centres, normals = (np.array(a) for a in zip(*(seq.base_in_camera(k) for k in range(len(seq)))))
    frames = {
        n: measure_frames(
            seq.images,
            seq.camera,
            moved,
            t_moved,
            odo,
            odo_std,
            FeatureConfig(max_features=n - 1),
            teammate_config("refined", radius),
        )[0]
        for n in N_VALUES
    }
    return {
        "schedule": schedule,
        "seed": seed,
        "frames": frames,
        "camera": seq.camera,
        "truth": seq.t_wc,
        "R_wc": seq.R_wc,
        "base_normal": seq.base_normal,
        "centres": centres,
        "normals": normals,
        "radius": radius,
        "pixel_pitch": seq.config.pixel_pitch,
        "depth": seq.config.background_distance,
    }


def with_tracker(m: dict, n: int, reading: dict) -> list:
    """Frames of N = n with the reading's tracker: centre errors of per-axis std
    reading["tracker_sd_cm"] and tilt std tracker_scale x TILT_DEG (None: the rendered
    front-end's)."""
    frames = m["frames"][n]
    if reading["tracker_sd_cm"] is None:
        return frames
    tilt = np.radians([TILT_DEG] * 2) * reading["tracker_scale"]
    sd = np.concatenate([np.asarray(reading["tracker_sd_cm"]) / 100.0, tilt])
    cov = np.tile(np.diag(sd**2), (len(frames), 1, 1))
    rng = np.random.default_rng([m["seed"], 3])  # the same draws for every N
    return with_teammate_from_geometry(
        frames,
        m["camera"],
        m["centres"],
        m["normals"],
        teammate_config("refined", m["radius"]),
        cov,
        rng,
    )


def tracker_errors(m: dict, frames: list) -> np.ndarray:
    """(3,) largest absolute camera-frame error of the genuine circle centre [cm]."""
    normals_cam = np.einsum("kji,kj->ki", m["R_wc"], m["base_normal"])
    genuine = genuine_candidates(frames, normals_cam)
    err = [
        np.abs(f.teammate.candidates.t[g] - m["centres"][k])
        for k, (f, g) in enumerate(zip(frames, genuine))
        if f.teammate is not None and g >= 0
    ]
    return 100.0 * np.max(err, axis=0) if err else np.full(3, np.nan)


def ekf_errors(m: dict, frames: list, tracker_variance: float, feature_sigma: float):
    """(3,) mean absolute translation error per axis [cm] of the seed's EKF."""
    cfg = EkfConfig(
        feature_depth=m["depth"],
        feature_sigma=feature_sigma,
        tracker_variance=tracker_variance,
        tracker_setting="proper",
        pixel_pitch=m["pixel_pitch"],
    )
    return 100.0 * np.abs(run_ekf(frames, m["camera"], cfg) - m["truth"]).mean(axis=0)


def graphloc_errors(m: dict, frames: list, feature_sigma: float) -> np.ndarray:
    """(3,) mean absolute translation error per axis [cm] of graphloc's batch estimate."""
    cfg = CooperativeSfmConfig(feature_prior_depth=m["depth"], feature_prior_sigma=feature_sigma)
    run = run_cooperative_sfm(frames, m["camera"], cfg)
    return 100.0 * np.abs(np.asarray(run.final_positions) - m["truth"]).mean(axis=0)


def trend(errors) -> float:
    """Least-squares slope of the errors (one per N_VALUES) against log N."""
    return float(np.polyfit(np.log(N_VALUES), np.asarray(errors, float), 1)[0])


def evaluate(measured: list, reading: dict, with_graphloc: bool = False) -> dict:
    """A reading over the trials of its schedule: per N the mean per-axis error of the EKF
    (and graphloc), the tracker's largest errors, the two claims and the Fig. 3 deviation."""
    trials = [m for m in measured if m["schedule"] == reading["schedule"]]
    ekf = {n: [] for n in N_VALUES}
    ours = {n: [] for n in N_VALUES}
    tracker = []
    for m in trials:
        for n in N_VALUES:
            frames = with_tracker(m, n, reading)
            if n == N_VALUES[-1]:
                tracker.append(tracker_errors(m, frames))
            ekf[n].append(
                ekf_errors(m, frames, reading["tracker_variance"], reading["feature_sigma"])
            )
            if with_graphloc:
                ours[n].append(graphloc_errors(m, frames, reading["feature_sigma"]))
    mean = {n: np.mean(ekf[n], axis=0) for n in N_VALUES}
    tx = [mean[n][0] for n in N_VALUES]
    tz = [mean[n][2] for n in N_VALUES]
    fig3 = np.nanmean(tracker, axis=0)
    dev = np.abs(fig3 / FIG3_RANGE_CM - 1.0)
    row = {
        **reading,
        "trials": len(trials),
        "ekf_cm": {n: mean[n].tolist() for n in N_VALUES},
        "tracker_max_cm": fig3.tolist(),
        "fig3_deviation": dev.tolist(),
        # read as trends ("tends to"): the sign of the error's least-squares slope in log N;
        # the strict readings beside: N = 1, 2 both below N = 10, 20 / T_z falling every step
        "claim_tx_small_n_better": bool(trend(tx) > 0),
        "claim_tz_improves_with_n": bool(trend(tz) < 0),
        "strict_tx": bool(max(tx[:2]) < min(tx[2:])),
        "strict_tz": bool(all(np.diff(tz) < 0)),
        "max_deviation": float(np.max(dev)) if np.isfinite(dev).all() else float("inf"),
    }
    row["reproduces"] = bool(
        row["claim_tx_small_n_better"]
        and row["claim_tz_improves_with_n"]
        and row["max_deviation"] <= 0.10
    )
    if with_graphloc:
        row["graphloc_cm"] = {n: np.mean(ours[n], axis=0).tolist() for n in N_VALUES}
    return row


def readings() -> list[dict]:
    """Every reading, the stated one first."""
    grid = itertools.product(TRACKER_SCALES, TRACKER_VARIANCES, FEATURE_SIGMAS, SCHEDULES)
    rows = [
        dict(
            tracker_scale=s,
            tracker_sd_cm=None if s == 0.0 else (s * FIG3_RANGE_CM / 2).tolist(),
            tracker_variance=v,
            feature_sigma=f,
            schedule=k,
        )
        for s, v, f, k in grid
    ]
    return sorted(rows, key=lambda r: r != STATED)


def choose(rows: list[dict]) -> dict:
    """The reading that shows both claims with the smallest Fig. 3 deviation (the stated one
    first among equals); without a reading showing both claims, the smallest deviation."""
    both = [r for r in rows if r["claim_tx_small_n_better"] and r["claim_tz_improves_with_n"]]
    pool = both or rows
    best = min(pool, key=lambda r: r["max_deviation"])
    strict = [r for r in rows if r.get("strict_tx") and r.get("strict_tz")]
    return {
        "best": best,
        "reproduces": best["reproduces"],
        "reproducing_readings": sum(r["reproduces"] for r in rows),
        "readings_with_both_claims": len(both),
        "readings_with_both_strict": len(strict),
        "strict_within_tol": sum(r["max_deviation"] <= 0.10 for r in strict),
    }


def refine(measured: list, best: dict, rounds: int = REFINE_ROUNDS) -> list:
    """Per-axis tracker stds fitted to Fig. 3 around the chosen reading: each round scales
    every axis's std by (Fig. 3's range / the measured largest error), the rest of the reading
    kept. Nothing to refine for the rendered tracker."""
    rows, row = [], best
    for level in range(rounds):
        if row["tracker_sd_cm"] is None or not np.isfinite(row["tracker_max_cm"]).all():
            break
        if row["max_deviation"] < 1e-3:  # already on Fig. 3 (the draws are fixed)
            break
        sd = np.asarray(row["tracker_sd_cm"]) * FIG3_RANGE_CM / np.asarray(row["tracker_max_cm"])
        reading = {k: row[k] for k in STATED} | {"tracker_sd_cm": sd.tolist()}
        row = {**evaluate(measured, reading), "stage": f"refined {level + 1}"}
        rows.append(row)
    return rows


def run_all(trials: int, workers: int, seed_offset: int = 0, progress: bool = True) -> dict:
    """Render and measure `trials` sequences per schedule, sweep every reading with the EKF,
    then the seed's EKF and graphloc at the stated and the chosen reading."""
    jobs = [(k, seed_offset + i) for k in SCHEDULES for i in range(trials)]
    with TrialExecutor(workers, progress=progress) as ex:
        measured = list(ex.imap(_measure, jobs, desc="seed 003 sequences"))
    rows = [{**evaluate(measured, r), "stage": "coarse"} for r in readings()]
    rows += refine(measured, choose(rows)["best"])
    choice = choose(rows)
    keys = tuple(STATED)
    best = {k: choice["best"][k] for k in keys}
    return {
        "trials": trials,
        "rows": rows,
        "choice": choice,
        "runs": {
            "stated": evaluate(measured, STATED, with_graphloc=True),
            "reproducing": evaluate(measured, best, with_graphloc=True),
        },
    }
