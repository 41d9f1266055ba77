"""Targets of four identical markers: every camera pose in the target frame that 4 (or 3)
detected blobs allow, seed 001 (001_0f8f8dae37ce6b79.txt) section IV-C: all 24 marker
assignments x up to 4 P3P solutions in one batched `solve_p3p` call, the fourth marker's
reprojection removing the wrong ones, a predicted pose restricting the assignments. Every pose
here is the camera in the target frame, T_target_camera (X_target = R_TC X_cam + t_cam,T).
The seed's target design (III-A) and pose prediction (IV-A): benchmarks/baselines/seed001_target.py.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Sequence

import cv2
import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.geometry.p3p import solve_p3p

# ----------------------------------------------------------------------------- targets


@dataclass(frozen=True)
class MarkerTarget:
    """Marker centres `points` (m,3) [m] in the target frame and the marker diameter b [m]."""

    points: np.ndarray
    marker_diameter: float
    name: str = ""

    def __post_init__(self):
        p = np.asarray(self.points, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) < 4:
            raise ValueError(f"MarkerTarget.points must be (m>=4, 3), got {p.shape}")
        if not np.isfinite(p).all():
            raise ValueError("MarkerTarget.points contains NaN/inf")
        if not (np.isfinite(self.marker_diameter) and self.marker_diameter > 0):
            raise ValueError(
                f"MarkerTarget.marker_diameter must be positive, got {self.marker_diameter}"
            )
        object.__setattr__(self, "points", p)

    def scaled(self, factor: float, name: str = "") -> "MarkerTarget":
        return MarkerTarget(
            self.points * factor, self.marker_diameter * factor, name or f"{self.name}x{factor:g}"
        )


# Seed 001 III-A: the larger target (vertices in cm, marker diameter b = 3 cm).
LARGE_TARGET = MarkerTarget(
    np.array(
        [[0.00, -16.51, 23.66], [0.00, 13.04, 18.45], [6.26, -2.21, 5.39], [-8.02, 2.49, 6.21]]
    )
    / 100.0,
    0.03,
    "seed001-large",
)
# Seed 001 III: the e-puck targets have the same proportions at half the size (b = 1.5 cm passive).
SMALL_TARGET = LARGE_TARGET.scaled(0.5, "seed001-small")


# ----------------------------------------------------------------------------- prediction


def as_pose3(pose) -> gtsam.Pose3:
    if isinstance(pose, gtsam.Pose3):
        return pose
    R, t = pose
    return gtsam.Pose3(gtsam.Rot3(np.asarray(R, dtype=float)), np.asarray(t, dtype=float))


def project_markers(
    camera, target: MarkerTarget, R_tc: np.ndarray, t_tc: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (..., m, 2) and visible mask (..., m) of the target's markers for camera poses
    R_tc (...,3,3), t_tc (...,3) in the target frame (seed 001 IV-A, q = K [R^T | -R^T t] p)."""
    R = np.asarray(R_tc, dtype=float)
    t = np.asarray(t_tc, dtype=float)
    batch = R.shape[:-2]
    X_cam = np.einsum("...ji,...mj->...mi", R, target.points - t[..., None, :])
    px, vis = camera.project(X_cam.reshape(-1, 3))
    m = len(target.points)
    return px.reshape(*batch, m, 2), vis.reshape(*batch, m)


def predicted_marker_pixels(camera, target: MarkerTarget, pose) -> tuple[np.ndarray, np.ndarray]:
    """Predicted marker pixels (m,2) + visible (m,) for a predicted camera pose (gtsam.Pose3 or
    (R,t))."""
    p = as_pose3(pose)
    return project_markers(camera, target, p.rotation().matrix(), p.translation())


# ----------------------------------------------------------------------------- hypotheses


@dataclass(frozen=True)
class TargetHypothesisConfig:
    """gate_px: the fourth marker must reproject this close to its detection (seed IV-C).
    pixel_sigma: score = exp(-rms^2 / (2 sigma^2)) with rms over all markers [px].
    prediction_gate_px: with a prediction, marker j may take detection i only if it lies this
    close to marker j's predicted pixel (or is the nearest detection to it).
    refine: polish each surviving hypothesis on all four markers (cv2.solvePnPRefineLM, pinhole
    cameras with 4 blobs only); False keeps the seed's pure P3P pose."""

    gate_px: float = 3.0
    pixel_sigma: float = 1.0
    prediction_gate_px: float = 25.0
    refine: bool = True


PERMUTATIONS = np.array(list(itertools.permutations(range(4))), dtype=int)  # (24,4)
# three detections: which marker is unseen x order -> (24,4) with -1 for the unseen marker
_PARTIAL = np.array(
    [np.insert(p, m, -1) for p in itertools.permutations(range(3)) for m in range(4)], dtype=int
)
# four detections, one of them not a marker: drop each in turn -> (96,4)
_THREE_OF_FOUR = np.concatenate(
    [
        np.where(_PARTIAL >= 0, np.delete(np.arange(4), drop)[np.maximum(_PARTIAL, 0)], -1)
        for drop in range(4)
    ]
)


def _check_detections(detections) -> np.ndarray:
    det = np.asarray(detections, dtype=float)
    if det.ndim != 2 or det.shape[1] != 2 or len(det) not in (3, 4):
        raise ValueError(f"target_hypotheses: detections must be (4,2) (or (3,2)), got {det.shape}")
    if not np.isfinite(det).all():
        raise ValueError("target_hypotheses: detections contain NaN/inf")
    rounded = np.round(det, 6)
    if (rounded[:, None] == rounded[None]).all(axis=2).sum() > len(det):  # a pair beside i == i
        raise ValueError("target_hypotheses: two detections coincide")
    return det


def target_hypotheses_frames(
    detections: Sequence,
    camera,
    target: MarkerTarget = LARGE_TARGET,
    config: TargetHypothesisConfig = TargetHypothesisConfig(),
    predicted: Sequence | None = None,
    times: Sequence[float] | None = None,
    observer: str = "",
    observed: str = "",
) -> list[CandidateSet]:
    """All plausible camera poses in the target frame, one CandidateSet per frame, from
    detections[i]: (4,2) or (3,2) pixels in any order; predicted[i]: None or a predicted pose
    restricting the assignments (all are tried when none is compatible). With 4 detections,
    hypotheses whose fourth marker misses its detection by more than `gate_px` are dropped;
    when none passes, every 3-of-4 subset is tried (meta["fallback"] = "three_of_four"). With 3
    (one marker lost, seed V-A) every P3P solution is returned. The frames of one blob count go
    through each stage together, in a few batched calls. Bad detections raise ValueError."""
    n = len(detections)
    predicted = [None] * n if predicted is None else list(predicted)
    times = [0.0] * n if times is None else list(times)
    dets = [_check_detections(d) for d in detections]
    if len(target.points) != 4:
        raise ValueError(
            f"target_hypotheses: needs a 4-marker target, got {len(target.points)} markers"
        )
    out: list = [None] * n
    for count in (4, 3):
        frames = [i for i in range(n) if len(dets[i]) == count]
        if not frames:
            continue
        det = np.stack([dets[i] for i in frames])
        bearings, ok = camera.pixel_to_bearing(det.reshape(-1, 2))
        ok = ok.reshape(len(frames), count)
        if not ok.all():
            bad = ok[int(np.flatnonzero(~ok.all(axis=1))[0])]
            raise ValueError(
                f"target_hypotheses: detections {np.flatnonzero(~bad).tolist()} have no bearing"
            )
        bearings = bearings.reshape(len(frames), count, 3)
        pred_px = np.full((len(frames), 4, 2), np.nan)
        has_pred = np.array([predicted[i] is not None for i in frames])
        for f in np.flatnonzero(has_pred):
            pred_px[f] = predicted_marker_pixels(camera, target, predicted[frames[f]])[0]
        full = count == 4
        result = _hypotheses(
            det,
            bearings,
            PERMUTATIONS if full else _PARTIAL,
            camera,
            target,
            config,
            pred_px,
            has_pred,
            full,
        )
        parts = _by_frame(result, len(frames))
        fallback = [""] * len(frames)
        empty = [f for f in range(len(frames)) if full and len(parts[f][0]) == 0]
        if empty:  # no 4-blob hypothesis passes the gate: every 3-of-4 subset
            again = _hypotheses(
                det[empty],
                bearings[empty],
                _THREE_OF_FOUR,
                camera,
                target,
                config,
                pred_px[empty],
                has_pred[empty],
                False,
            )
            for f, part in zip(empty, _by_frame(again, len(empty))):
                parts[f], fallback[f] = part, "three_of_four"
        for f, i in enumerate(frames):
            R, t, cand_assign, gate_err, rms, n_assign, prediction_used = parts[f]
            out[i] = CandidateSet(
                R=R,
                t=t,
                scores=np.exp(-0.5 * (rms / config.pixel_sigma) ** 2),
                time=float(times[i]),
                observer=observer,
                observed=observed,
                source="seed001/target",
                meta={
                    "assignment": cand_assign,
                    "reprojection_px": rms,
                    "gate_error_px": gate_err,
                    "n_assignments": n_assign,
                    "prediction_used": prediction_used,
                    "fallback": fallback[f],
                    "frame": "camera pose in target frame (T_target_camera)",
                },
            )
    return out


def _by_frame(result: tuple, frames: int) -> list:
    """`_hypotheses`' candidates (sorted by frame) split into one tuple per frame: R, t,
    assignment, gate error, rms, number of assignments tried, whether the prediction was used."""
    frame, R, t, cand_assign, gate_err, rms, n_assign, prediction_used = result
    edges = np.searchsorted(frame, np.arange(frames + 1))
    return [
        tuple(a[edges[f] : edges[f + 1]] for a in (R, t, cand_assign, gate_err, rms))
        + (int(n_assign[f]), bool(prediction_used[f]))
        for f in range(frames)
    ]


def _hypotheses(det, bearings, assign, camera, target, config, pred_px, has_pred, gated):
    """P3P for every assignment row (marker j <- detection assign[j], -1 unseen) of every frame
    (det (F,n,2), bearings (F,n,3)) in ONE batched call, fourth-marker gate (if `gated`),
    optional refinement. pred_px (F,4,2): predicted marker pixels of the frames with a
    prediction (has_pred (F,)). Returns per candidate, sorted by frame: its frame, R, t,
    assignment, gate error, rms reprojection; per frame: the number of assignments tried and
    whether the prediction was used."""
    n_frames, n_rows = len(det), len(assign)
    rows_ok = np.ones((n_frames, n_rows), dtype=bool)
    prediction_used = np.zeros(n_frames, dtype=bool)
    if has_pred.any():
        d = np.linalg.norm(pred_px[:, :, None] - det[:, None], axis=3)  # (F, marker, detection)
        d = np.where(np.isfinite(d), d, np.inf)
        allowed = (d <= config.prediction_gate_px) | (d == d.min(axis=2, keepdims=True))
        markers = np.arange(4)[None].repeat(n_rows, 0)
        ok_rows = np.where(assign >= 0, allowed[:, markers, np.maximum(assign, 0)], True).all(
            axis=2
        )
        prediction_used = has_pred & ok_rows.any(axis=1)
        rows_ok[prediction_used] = ok_rows[prediction_used]
    seen = np.argsort(assign < 0, axis=1, kind="stable")  # marker indices, seen ones first
    det_idx = np.take_along_axis(assign, seen[:, :3], axis=1)
    fi, ai = np.nonzero(rows_ok)  # the instances, frame by frame
    sol = solve_p3p(bearings[fi[:, None], det_idx[ai]], target.points[seen[ai, :3]])
    N = len(fi)
    valid = sol.valid.reshape(N * 4)
    R = sol.R_wc.reshape(N * 4, 3, 3)[valid]
    t = sol.t_wc.reshape(N * 4, 3)[valid]
    frame = np.repeat(fi, 4)[valid]
    cand_assign = np.repeat(assign[ai], 4, axis=0)[valid]
    check_marker = np.repeat(seen[ai, 3], 4)[valid]  # the fourth marker
    err = _marker_errors(camera, target, R, t, cand_assign, det[frame])
    if gated:  # seed IV-C: drop hypotheses whose fourth marker does not fit
        gate_err = err[np.arange(len(R)), check_marker]
        keep = gate_err <= config.gate_px
    else:
        gate_err = np.zeros(len(R))
        keep = np.isfinite(err).all(axis=1)
    frame, R, t, cand_assign, gate_err = (a[keep] for a in (frame, R, t, cand_assign, gate_err))
    if config.refine and gated and len(R) and hasattr(camera, "K"):
        R, t = _refine(R, t, cand_assign, det[frame], camera, target)
    err = _marker_errors(camera, target, R, t, cand_assign, det[frame])
    finite = np.isfinite(err).all(axis=1)
    frame, R, t, cand_assign, gate_err, err = (
        a[finite] for a in (frame, R, t, cand_assign, gate_err, err)
    )
    rms = np.sqrt((err**2).sum(axis=1) / (cand_assign >= 0).sum(axis=1))
    return frame, R, t, cand_assign, gate_err, rms, rows_ok.sum(axis=1), prediction_used


def _marker_errors(camera, target, R, t, assign, det) -> np.ndarray:
    """(K,4) reprojection error [px] of every seen marker (0 for the unseen one, inf behind the
    camera); det (K,n,2): each hypothesis's detections."""
    if len(R) == 0:
        return np.zeros((0, 4))
    px, _ = project_markers(camera, target, R, t)
    picked = np.take_along_axis(det, np.maximum(assign, 0)[:, :, None], axis=1)
    err = np.linalg.norm(px - picked, axis=2)
    err = np.where(np.isfinite(err), err, np.inf)
    return np.where(assign >= 0, err, 0.0)


def _refine(R, t, assign, det, camera, target):
    """Levenberg-Marquardt on all seen markers of each hypothesis (cv2.solvePnPRefineLM; det
    (K,n,2) each hypothesis's detections); the loop runs over the few survivors of the P3P
    stage only."""
    K, dist = camera.K, np.asarray(camera.dist, dtype=float)
    R_out, t_out = R.copy(), t.copy()
    for k in range(len(R)):
        seen = assign[k] >= 0
        R_ct = R[k].T
        rvec, _ = cv2.Rodrigues(R_ct)
        tvec = (-R_ct @ t[k]).reshape(3, 1)
        rvec, tvec = cv2.solvePnPRefineLM(
            target.points[seen].reshape(-1, 1, 3),
            det[k][assign[k][seen]].reshape(-1, 1, 2),
            K,
            dist,
            rvec,
            tvec,
        )
        R_new = cv2.Rodrigues(rvec)[0].T
        t_new = -R_new @ tvec.ravel()
        if np.isfinite(R_new).all() and np.isfinite(t_new).all():
            R_out[k], t_out[k] = R_new, t_new
    return R_out, t_out
