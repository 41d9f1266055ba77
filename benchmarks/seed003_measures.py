"""Seed 003 (003_8db27855ce2d5f68.txt) benchmark, what one trial measures besides the
estimators: the teammate front-end's circle errors against the truth and against the
Cramér-Rao bound of the images (section II-A), KLT track errors by age (section II-B), the
camera displacement a circle cannot see, the cost of one max-mixture linearization, the
per-axis error and trajectory scale of Fig. 6; the method and front-end names of
benchmarks.seed003."""

from __future__ import annotations

import time

import cv2
import gtsam
import numpy as np

from graphloc.datasets.textured_scene import disk_coverage
from graphloc.factors.mixture import max_mixture_factor
from graphloc.keys import pose_key
from graphloc.vision.circle import circle_pose_from_rim, rotations_from_normals
from graphloc.vision.base_rim import BlobConfig, detect_base_rim
from graphloc.vision.teammate import TeammateConfig

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
AXES = ("x", "y", "z")


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
            for i, point in zip(ids[new].tolist(), surface_points(seq, k, pixels[new])):
                first[i] = (k, point)
        if (~new).any():
            k0, points = zip(*(first[i] for i in ids[~new].tolist()))
            uv, _ = seq.camera.project((np.array(points) - seq.t_wc[k]) @ seq.R_wc[k])
            ages.extend(k - np.array(k0))
            errors.extend(np.linalg.norm(uv - pixels[~new], axis=1))
    return np.array(ages, dtype=int), np.array(errors)


def unseen_displacement(seq, k: int) -> float:
    """Camera displacement [m] at frame k that no circle measurement can show: the camera's
    true rotation since frame 0 about the disk-normal axis through the base centre (the image
    of a circle does not change under it) times the camera's distance from that axis."""
    normal = seq.base_normal[k] / np.linalg.norm(seq.base_normal[k])
    angle = float(gtsam.Rot3.Logmap(gtsam.Rot3(seq.R_wc[k] @ seq.R_wc[0].T)) @ normal)
    arm = seq.t_wc[k] - seq.base_centre[k]
    return abs(angle) * float(np.linalg.norm(arm - (arm @ normal) * normal))


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


def disk_information(generator, seq, k: int, subsamples: int = 32) -> np.ndarray:
    """(5,5) Fisher information of frame k's pixels about the base disk in camera k (centre x,
    y, z [m]; normal tilt towards the disk's x and y axes [rad], n + a x + b y, axes of
    `rotations_from_normals`) for `generator`'s (a CrawlerPairScenario) image model: coverage
    blend of the base colour over the KNOWN background, blur, white noise of variance
    noise_sigma^2 + 1/12 (the uint8 rounding) per channel. Its inverse is the Cramér-Rao bound of
    any unbiased estimate of the disk from that image (optimistic: a real front-end does not know
    the background behind the base). Derivatives of the coverage by central differences (0.2 mm
    across, 5 mm along z, 0.03 rad: the coverage is linear in edge shifts this small) at
    subsamples^2 rays per pixel."""
    cfg = generator.config
    cam = cfg.camera()
    centre, normal = seq.base_in_camera(k)
    R = rotations_from_normals(normal[None])[0]
    colour = np.float32(cfg.base_colour) - generator.background(seq.R_wc[k], seq.t_wc[k])
    steps = (2e-4, 2e-4, 5e-3, 3e-2, 3e-2)
    grads = []
    for i, h in enumerate(steps):
        pair = []
        for sign in (1.0, -1.0):
            c, n = centre.copy(), normal.copy()
            if i < 3:
                c[i] += sign * h
            else:
                n = n + sign * h * R[:, i - 3]
            pair.append(disk_coverage(cam, c, n / np.linalg.norm(n), cfg.base_radius, subsamples))
        d = (pair[0] - pair[1])[..., None] / (2.0 * h) * colour
        grads.append(cv2.GaussianBlur(d, (0, 0), cfg.blur_sigma) if cfg.blur_sigma > 0 else d)
    J = np.stack([g.reshape(-1) for g in grads], axis=1).astype(np.float64)  # (pixels * 3, 5)
    return J.T @ J / (cfg.noise_sigma**2 + 1.0 / 12.0)


def surface_points(seq, t: int, pixels: np.ndarray) -> np.ndarray:
    """World points (M,3) of the textured wall or ground (`seq.scene`) seen at `pixels` (M,2)
    of frame t: the ground truth of KLT features (the base is not a surface here)."""
    rays = seq.camera.pixel_to_bearing(pixels)[0] @ seq.R_wc[t].T
    o, scene = np.asarray(seq.t_wc[t], float), seq.scene
    with np.errstate(divide="ignore", invalid="ignore"):
        s_wall = (scene.wall_z - o[2]) / rays[:, 2]
        s_ground = (scene.ground_y - o[1]) / rays[:, 1]
    s_wall = np.where(s_wall > 0, s_wall, np.inf)
    s_ground = np.where(s_ground > 0, s_ground, np.inf)
    s = np.minimum(s_wall, s_ground)
    hits = o + s[:, None] * rays
    hits[~np.isfinite(s)] = np.nan
    return hits


# ---- seed 003 (003_8db27855ce2d5f68.txt, Fig. 6): per-axis error and trajectory scale -----
def axis_errors(estimated: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(T,3) absolute translation error per axis (the seed's Fig. 6 quantity)."""
    estimated, truth = np.asarray(estimated, float), np.asarray(truth, float)
    if estimated.shape != truth.shape or estimated.ndim != 2 or estimated.shape[1] != 3:
        raise ValueError(
            f"axis_errors: shapes {estimated.shape} vs {truth.shape}, expected equal (T,3)"
        )
    return np.abs(estimated - truth)


def trajectory_scale(estimated: np.ndarray, truth: np.ndarray) -> float:
    """Least-squares scale s of the lengths of the estimated displacements from frame 0 against
    the true ones, s = sum |p||q| / sum |q|^2 (lengths, so that a direction error is not
    counted as a scale error; the gauge fixes frame 0); NaN when the camera has not moved."""
    p = np.asarray(estimated, float) - np.asarray(estimated, float)[0]
    q = np.asarray(truth, float) - np.asarray(truth, float)[0]
    if p.shape != q.shape:
        raise ValueError(f"trajectory_scale: shapes {p.shape} vs {q.shape}")
    qq = float(np.sum(q * q))
    return (
        float(np.sum(np.linalg.norm(p, axis=1) * np.linalg.norm(q, axis=1)) / qq)
        if qq > 0
        else float("nan")
    )


def scale_errors(history, truth: np.ndarray) -> np.ndarray:
    """(T,) |s_k - 1| where s_k = trajectory_scale of what was known at frame k (history[k]:
    (k+1,3) positions of frames 0..k) against truth[:k+1]."""
    truth = np.asarray(truth, float)
    return np.array([abs(trajectory_scale(h, truth[: len(h)]) - 1.0) for h in history])
