"""Seed 003 (003_8db27855ce2d5f68.txt) measurements from known geometry: the front-end
bypassed, for tests and ablations. `ideal_frames` builds `graphloc.seams.FrameInput`s from
world points and base centres (sections II-A / II-B quantities with chosen noise);
`with_teammate_from_geometry` replaces each sighting's circle candidates by those of the true
disk (exact, or moved by a draw from a given covariance such as the Cramér-Rao bound of the
crawler-pair images); `genuine_candidates` names the candidate nearest the true normal;
`rim_points_from_mask` the rim of a binary mask (seed 003 II-A-1).
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.candidates import CandidateSet
from graphloc.factors.mixture import check_covariances
from graphloc.seams import FrameInput, TeammateObservation
from graphloc.datasets.render import render_circle_rim
from graphloc.vision.circle import circle_pose_from_rim, rotations_from_normals
from graphloc.vision.features import FrameFeatures
from graphloc.vision.images import opencv_errors
from graphloc.vision.teammate import TeammateConfig, teammate_observation


def genuine_candidates(frames: list[FrameInput], true_normals: np.ndarray) -> np.ndarray:
    """(T,) index of the circle candidate whose normal is closest to the true disk normal
    (T,3, camera frame) -- the genuine one -- and -1 where the teammate was not seen."""
    true_normals = np.asarray(true_normals, float)
    if true_normals.shape != (len(frames), 3):
        raise ValueError(
            f"genuine_candidates: true_normals must be ({len(frames)},3), got {true_normals.shape}"
        )
    out = np.full(len(frames), -1)
    for k, f in enumerate(frames):
        if f.teammate is not None and f.teammate.candidates is not None:
            out[k] = int(np.argmax(f.teammate.candidates.R[:, :, 2] @ true_normals[k]))
    return out


def ideal_frames(
    camera: PinholeCamera,
    R_wc: np.ndarray,
    t_wc: np.ndarray,
    points: np.ndarray,
    base_centres: np.ndarray,
    camera_moved,
    teammate_moved,
    teammate_odometry,
    teammate_odometry_std,
    pixel_sigma: float = 0.5,
    centre_sigmas: tuple[float, float] = (2e-4, 1e-3),
    rng: np.random.Generator | None = None,
    base_normals: np.ndarray | None = None,
    base_radius: float = 0.019,
    normal_sigma: float = 0.01,
) -> list[FrameInput]:
    """FrameInputs computed from geometry instead of pixels: world points (P,3) projected into
    cameras (T,3,3)/(T,3) with N(0, pixel_sigma) noise (ids = point indices, only visible ones),
    the base centre (T,3) seen in the camera frame with lateral / depth sigmas `centre_sigmas`
    [m] (NaN rows: teammate not seen). The circle candidates come from the exact rim of the
    base disk (world normals base_normals (T,3), default facing camera 0: -z; radius
    base_radius) through `circle_pose_from_rim` -- the genuine and the mirrored solution --
    then both get the same centre noise and each its own normal noise (normal_sigma [rad])."""
    rng = np.random.default_rng(0) if rng is None else rng
    R_wc, t_wc = np.asarray(R_wc, float), np.asarray(t_wc, float)
    T = len(R_wc)
    points = np.asarray(points, float).reshape(-1, 3)
    base_centres = np.asarray(base_centres, float).reshape(T, 3)
    normals_w = (
        np.tile([0.0, 0.0, -1.0], (T, 1))
        if base_normals is None
        else np.asarray(base_normals, float).reshape(T, 3)
    )
    normal_rng = np.random.default_rng(
        rng.bit_generator.seed_seq.spawn(1)[0]
    )  # leaves rng's stream as is
    frames = []
    for k in range(T):
        pc = (points - t_wc[k]) @ R_wc[k]
        uv, vis = camera.project(pc)
        ids = np.flatnonzero(vis)
        pixels = uv[ids] + pixel_sigma * rng.normal(size=(len(ids), 2))
        obs = None
        if np.isfinite(base_centres[k]).all():
            c = R_wc[k].T @ (base_centres[k] - t_wc[k])
            d = c / np.linalg.norm(c)
            lat, dep = centre_sigmas
            cov = lat**2 * (np.eye(3) - np.outer(d, d)) + dep**2 * np.outer(d, d)
            rim, _ = render_circle_rim(
                camera, c, R_wc[k].T @ normals_w[k], base_radius, n_points=64
            )
            exact, _ = circle_pose_from_rim(camera, rim, base_radius)
            noise = np.linalg.cholesky(cov) @ rng.normal(size=3)
            tilt = normal_rng.normal(
                0.0, normal_sigma, size=(len(exact), 2)
            )  # about the candidate's x, y axes
            normals = exact.R[:, :, 2] + np.einsum("kij,kj->ki", exact.R[:, :, :2], tilt)
            R_c = rotations_from_normals(normals / np.linalg.norm(normals, axis=1, keepdims=True))
            cands = CandidateSet(
                R_c,
                exact.t + noise,
                exact.scores,
                float(k),
                "camera",
                "teammate",
                "circle",
                meta=exact.meta,
            )
            noisy = cands.t.mean(axis=0)
            pixel, _ = camera.project(noisy[None])
            obs = TeammateObservation(noisy, cov, pixel[0], len(cands), 0.0, 0.0, cands, cov)
        frames.append(
            FrameInput(
                float(k),
                FrameFeatures(ids.astype(np.int64), pixels),
                obs,
                bool(camera_moved[k]),
                bool(teammate_moved[k]),
                float(teammate_odometry[k]),
                float(teammate_odometry_std[k]),
            )
        )
    return frames


def with_teammate_from_geometry(
    frames: list[FrameInput],
    camera: PinholeCamera,
    centres: np.ndarray,
    normals: np.ndarray,
    config: TeammateConfig = TeammateConfig(),
    disk_covariances: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
) -> list[FrameInput]:
    """The same frames with every sighting's circle candidates replaced by those of the rim of
    the base disk from known geometry (camera-frame centres (T,3), unit normals (T,3), radius
    config.radius); everything else (KLT tracks, motion flags, odometry) unchanged. An
    ablation for scripts/bench_seed003.py (seed 003 II-A: a circle gives its centre and normal,
    never the rotation about the normal):
      - disk_covariances None: the EXACT disk (a perfect circle front-end), with the calibrated
        covariance of `teammate_observation`;
      - disk_covariances (T,5,5) (parametrization of TeammateObservation.disk_covariance): the
        disk is first moved by a draw from N(0, disk_covariances[k]) (rng), and the observation
        carries that covariance -- a front-end whose errors are exactly those, e.g. at the
        Cramér-Rao bound of the image."""
    centres, normals = np.asarray(centres, float), np.asarray(normals, float)
    for name, a in (("centres", centres), ("normals", normals)):
        if a.shape != (len(frames), 3):
            raise ValueError(
                f"with_teammate_from_geometry: {name} must be ({len(frames)},3), got {a.shape}"
            )
    if disk_covariances is not None:
        disk_covariances = np.asarray(disk_covariances, float)
        if disk_covariances.shape != (len(frames), 5, 5):
            raise ValueError(
                f"with_teammate_from_geometry: disk_covariances must be ({len(frames)},5,5), "
                f"got {disk_covariances.shape}"
            )
        check_covariances(disk_covariances, "with_teammate_from_geometry: disk_covariances")
        rng = np.random.default_rng(0) if rng is None else rng
    out = []
    for k, f in enumerate(frames):
        if f.teammate is None:
            out.append(f)
            continue
        if not (
            np.isfinite(centres[k]).all() and np.isfinite(normals[k]).all() and centres[k, 2] > 0
        ):
            raise ValueError(
                f"with_teammate_from_geometry: frame {k} was a sighting but its true centre "
                f"{centres[k]} / normal {normals[k]} is not a finite disk in front of the camera"
            )
        centre, normal = centres[k], normals[k] / np.linalg.norm(normals[k])
        if disk_covariances is not None:
            draw = np.linalg.cholesky(disk_covariances[k]) @ rng.normal(size=5)
            centre = centre + draw[:3]
            normal = normal + rotations_from_normals(normal[None])[0][:, :2] @ draw[3:]
            normal = normal / np.linalg.norm(normal)
        rim, visible = render_circle_rim(camera, centre, normal, config.radius, n_points=256)
        cands, _ = circle_pose_from_rim(
            camera,
            rim[visible],
            config.radius,
            config.circle,
            time=f.time,
            observer="camera",
            observed="teammate",
        )
        obs = teammate_observation(cands, camera, config)
        if disk_covariances is not None:
            obs = replace(
                obs,
                candidate_covariance=disk_covariances[k][:3, :3].copy(),
                disk_covariance=disk_covariances[k].copy(),
            )
        out.append(replace(f, teammate=obs))
    return out


def rim_points_from_mask(mask: np.ndarray) -> np.ndarray:
    """Boundary pixels (M,2) (u, v) of the largest blob of a binary mask (seed 003 II-A-1:
    colour threshold -> median filter -> edges), via cv2.findContours."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"mask must be a 2-D image, got shape {mask.shape}")
    if mask.dtype.kind not in "biuf":
        raise ValueError(f"mask must be a numeric or boolean image, got dtype {mask.dtype}")
    if mask.size == 0:
        raise ValueError(f"mask is empty (shape {mask.shape})")
    with opencv_errors(f"rim_points_from_mask on a {mask.shape[1]}x{mask.shape[0]} mask"):
        contours, _ = cv2.findContours(
            (mask > 0).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE
        )
    if not contours:
        raise ValueError("mask has no foreground blob")
    return max(contours, key=cv2.contourArea).reshape(-1, 2).astype(float)
