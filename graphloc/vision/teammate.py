"""Seed 003 (003_8db27855ce2d5f68.txt) front-end, pixels -> per-frame measurements: section II
"robot tracker" (the teammate's base rim -> both circle poses, `graphloc.vision.circle`, ->
their moment-matched centre with its first-order covariance) and II-B (KLT feature tracks
outside the base, `graphloc.vision.features`). `measure_frames` turns an image sequence into
the `graphloc.seams.FrameInput`s that the graph (`benchmarks.cooperative_sfm`) and the
seed's EKF (`benchmarks.baselines.ekf_seed003`) both take.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from tqdm import tqdm

from graphloc.cameras import PinholeCamera
from graphloc.candidates import CandidateSet
from graphloc.config_schema import config_dataclass, setting
from graphloc.seams import FrameInput, TeammateObservation
from graphloc.vision.circle import CircleConfig, circle_pose_from_rim
from graphloc.vision.base_rim import BlobConfig, detect_base_rim
from graphloc.vision.features import FeatureConfig, FeatureTracker


@config_dataclass
class TeammateConfig:
    """radius [m] of the base disk; blob: its colour signature; circle: ellipse-fit settings;
    radius_pixel_floor, centre_pixel_floor [px]: lower bounds of the ellipse radius and centre
    accuracy used for the centre covariance (how they were chosen: docs/design_algorithms.md)."""

    radius: float = setting(0.019, gt=0.0)
    blob: BlobConfig = BlobConfig()
    circle: CircleConfig = CircleConfig()
    radius_pixel_floor: float = setting(0.007, gt=0.0)
    centre_pixel_floor: float = setting(0.03, gt=0.0)


def pixel_sigmas(candidates: CandidateSet, config: TeammateConfig) -> tuple[float, float]:
    """(centre, radius) accuracy [px] of the ellipse behind `candidates`: the edge fit's sigmas
    when candidates.meta has them ('centre_sigma_px', 'radius_sigma_px'), else rms / sqrt(n / 2)
    and rms / sqrt(n) of the rim points, floored at the config's pixel floors."""
    rms = float(candidates.meta.get("rms_px", 0.0))
    n = max(int(candidates.meta.get("n_points", 1)), 1)
    sigma_r = max(
        float(candidates.meta.get("radius_sigma_px", rms / np.sqrt(n))), config.radius_pixel_floor
    )
    sigma_c = max(
        float(candidates.meta.get("centre_sigma_px", rms / np.sqrt(n / 2.0))),
        config.centre_pixel_floor,
    )
    return sigma_c, sigma_r


def teammate_observation(
    candidates: CandidateSet, camera: PinholeCamera, config: TeammateConfig
) -> TeammateObservation:
    """Moment-matched Gaussian of the circle candidates' centres (camera frame). Per candidate,
    first-order noise: the ellipse radius r_px is known to sigma_r = max(s_r, radius_pixel_floor)
    and its centre to sigma_c = max(s_c, centre_pixel_floor), where s_r, s_c are the edge fit's
    sigmas when candidates.meta has them ('radius_sigma_px', 'centre_sigma_px', set by
    `measure_frames` from a refined rim) and rms / sqrt(n), rms / sqrt(n / 2) of the rim points
    otherwise; depth sigma = z sigma_r / r_px and lateral sigma = z sigma_c / f."""
    if len(candidates) == 0:
        raise ValueError("teammate_observation: no circle candidates")
    w = candidates.weights()
    c = candidates.t
    mean = w @ c
    z = float(mean[2])
    if not z > 0:
        raise ValueError(f"teammate_observation: base centre behind the camera (z = {z})")
    sigma_c, sigma_r = pixel_sigmas(candidates, config)
    r_px = camera.fx * config.radius / z
    f = 0.5 * (camera.fx + camera.fy)
    direction = mean / np.linalg.norm(mean)
    along = np.outer(direction, direction)
    cov_single = (z * sigma_c / f) ** 2 * (np.eye(3) - along) + (z * sigma_r / r_px) ** 2 * along
    d = c - mean
    cov = cov_single + np.einsum("k,ki,kj->ij", w, d, d)
    pairs = (c[:, None, :] - c[None, :, :]).reshape(-1, 3)
    separation = float(
        np.sqrt(np.max(np.einsum("ni,ni->n", pairs, np.linalg.solve(cov_single, pairs.T).T)))
    )
    pixel, _ = camera.project(mean[None])
    return TeammateObservation(
        mean,
        0.5 * (cov + cov.T),
        pixel[0],
        len(candidates),
        float(np.linalg.norm(d, axis=1).max()),
        separation,
        candidates,
        cov_single,
    )


@dataclass(frozen=True)
class FrontEndReport:
    """Counts of what the front-end could not use: frames without a base blob, frames whose
    rim gave no circle (with the reasons), feature tracks lost; the largest distance [m] of a
    circle candidate's centre from the moment-matched centre, and the largest Mahalanobis
    separation of two candidate centres (<= 2: the centre mixture is unimodal) over the run."""

    no_blob: int
    circle_failed: int
    circle_reasons: tuple[str, ...]
    tracks_lost: int
    max_candidate_spread: float = 0.0
    max_candidate_separation: float = 0.0


def measure_frames(
    images: np.ndarray,
    camera: PinholeCamera,
    camera_moved,
    teammate_moved,
    teammate_odometry,
    teammate_odometry_std,
    features: FeatureConfig = FeatureConfig(),
    teammate: TeammateConfig = TeammateConfig(),
    times=None,
    progress: bool = False,
) -> tuple[list[FrameInput], FrontEndReport]:
    """Front-end over a frame sequence: base rim -> circle candidates -> moment-matched centre,
    KLT tracks outside the base. Motion flags / odometry are per frame (T,), entry 0 unused."""
    images = np.asarray(images)
    if images.ndim != 4 or images.shape[3] != 3 or images.dtype != np.uint8:
        raise ValueError(
            f"measure_frames: images must be (T,H,W,3) uint8, got {images.dtype} {images.shape}"
        )
    T = len(images)
    arrays = {}
    for name, arr in (
        ("camera_moved", camera_moved),
        ("teammate_moved", teammate_moved),
        ("teammate_odometry", teammate_odometry),
        ("teammate_odometry_std", teammate_odometry_std),
        ("times", np.arange(T, dtype=float) if times is None else times),
    ):
        a = np.asarray(arr, dtype=float)
        if a.shape != (T,):
            raise ValueError(f"measure_frames: {name} must have shape ({T},), got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(
                f"measure_frames: {name}[{int(np.flatnonzero(~np.isfinite(a))[0])}] is not finite"
            )
        arrays[name] = a
    bad = np.flatnonzero(np.diff(arrays["times"]) <= 0)
    if bad.size:
        raise ValueError(
            f"measure_frames: times[{bad[0] + 1}] = {arrays['times'][bad[0] + 1]} does not increase"
        )
    tracker = FeatureTracker(features)
    frames, reasons = [], []
    no_blob = lost = 0
    steps = range(T)
    if progress:
        steps = tqdm(steps, desc="front-end", leave=False)
    for t in steps:
        obs = None
        blob = detect_base_rim(images[t], teammate.blob)
        try:
            if blob is None:
                no_blob += 1
            elif blob.refine_error:
                reasons.append(f"frame {t}: {blob.refine_error}")
            else:
                cands, poses = circle_pose_from_rim(
                    camera,
                    blob.rim,
                    teammate.radius,
                    teammate.circle,
                    time=arrays["times"][t],
                    observer="camera",
                    observed="teammate",
                )
                cands = replace(cands, meta={**cands.meta, "ellipse": poses.ellipses[0].tolist()})
                if blob.refinement is not None:
                    fit = blob.refinement
                    cands = replace(
                        cands,
                        meta={
                            **cands.meta,
                            "radius_sigma_px": float(fit.semi_axis_sigma.max()),
                            "centre_sigma_px": float(fit.centre_sigma.max()),
                            "edge_blur_px": fit.blur,
                        },
                    )
                obs = teammate_observation(cands, camera, teammate)
        except ValueError as exc:
            reasons.append(f"frame {t}: {exc}")
        feats = tracker.step(images[t], None if blob is None else blob.exclusion)
        lost += feats.n_lost
        frames.append(
            FrameInput(
                float(arrays["times"][t]),
                feats,
                obs,
                bool(arrays["camera_moved"][t]),
                bool(arrays["teammate_moved"][t]),
                float(arrays["teammate_odometry"][t]),
                float(arrays["teammate_odometry_std"][t]),
            )
        )
    seen = [f.teammate for f in frames if f.teammate is not None]
    spread = max((o.candidate_spread for o in seen), default=0.0)
    separation = max((o.candidate_separation for o in seen), default=0.0)
    return frames, FrontEndReport(no_blob, len(reasons), tuple(reasons), lost, spread, separation)
