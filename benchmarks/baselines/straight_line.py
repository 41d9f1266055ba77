"""Seed 000 (000_05137a0a9c449be3.txt) section IV, the deterministic "linear movement" algorithm:
P3P on each of three snapshots taken while the climbing robot moves along a straight line
(steps 1-3), then over all <= 4x4x4 candidate combinations (step 4) the distance of the 2nd
camera position from the line through the 1st and 3rd (step 5); the smallest is genuine (step 6).
Vectorized over trials and combinations. `StraightLineBaseline` runs the same test on a stream
of CandidateSets with the engines' per-frame interface (graphloc.hypotheses)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from graphloc.candidates import CandidateSet
from graphloc.geometry.p3p import MAX_CANDIDATES, P3PCandidates, solve_p3p
from graphloc.seams import Decision, check_frame


@dataclass(frozen=True)
class StraightLineChoice:
    """Result for T trials. errors (T,4,4,4): line error of each combination (inf if a candidate
    is missing); chosen (T,3): candidate index per snapshot; error (T,): its line error;
    second_error (T,): next smallest error (inf if only one combination); found (T,): some
    combination exists. candidates: the per-snapshot P3P candidates, shaped (T*3,) in the order
    trial-major, snapshot-minor."""

    errors: np.ndarray
    chosen: np.ndarray
    error: np.ndarray
    second_error: np.ndarray
    found: np.ndarray
    candidates: P3PCandidates

    def chosen_positions(self) -> np.ndarray:
        """(T,3,3) camera centres of the chosen combination (NaN where none was found)."""
        t = self.candidates.t_wc.reshape(-1, 3, MAX_CANDIDATES, 3)
        pos = np.take_along_axis(t, self.chosen[:, :, None, None], axis=2)[:, :, 0]
        return np.where(self.found[:, None, None], pos, np.nan)


def straight_line_errors(positions: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """positions (T,3,K,3): candidate camera centres per snapshot; valid (T,3,K) ->
    (T,K,K,K) distance of snapshot-1 candidate j from the line through snapshot-0 candidate i
    and snapshot-2 candidate k (inf where a candidate is invalid or i and k coincide)."""
    positions = np.asarray(positions, dtype=float)
    valid = np.asarray(valid, dtype=bool)
    if positions.ndim != 4 or positions.shape[1] != 3 or positions.shape[3] != 3:
        raise ValueError(
            f"straight_line_errors: positions must be (T,3,K,3), got {positions.shape}"
        )
    if valid.shape != positions.shape[:3]:
        raise ValueError(
            f"straight_line_errors: valid must be {positions.shape[:3]}, got {valid.shape}"
        )
    p0 = positions[:, 0, :, None, None, :]  # i
    p1 = positions[:, 1, None, :, None, :]  # j
    p2 = positions[:, 2, None, None, :, :]  # k
    axis = p2 - p0
    length = np.linalg.norm(axis, axis=-1)
    with np.errstate(all="ignore"):
        dist = np.linalg.norm(np.cross(p1 - p0, axis), axis=-1) / length
    ok = (
        valid[:, 0, :, None, None]
        & valid[:, 1, None, :, None]
        & valid[:, 2, None, None, :]
        & (length > 1e-12)
    )
    return np.where(ok & np.isfinite(dist), dist, np.inf)


def pick_straight_line(positions: np.ndarray, valid: np.ndarray):
    """Seed 000 sec. IV step 6: (chosen (T,3) indices i, j, k; error (T,); second_error (T,);
    errors (T,K,K,K))."""
    errors = straight_line_errors(positions, valid)
    T, K = errors.shape[0], errors.shape[1]
    flat = errors.reshape(T, -1)
    order = np.argsort(flat, axis=1)[:, :2]
    best = flat[np.arange(T), order[:, 0]]
    second = flat[np.arange(T), order[:, 1]] if flat.shape[1] > 1 else np.full(T, np.inf)
    chosen = np.stack(np.unravel_index(order[:, 0], (K, K, K)), axis=1)
    return chosen, best, second, errors


def bearings_from_pixels(pixels: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(...,2) pixels of an undistorted pinhole camera -> (...,3) unit bearings
    (cv2.undistortPoints)."""
    pts = np.ascontiguousarray(np.asarray(pixels, dtype=float).reshape(-1, 1, 2))
    norm = cv2.undistortPoints(pts, np.asarray(K, dtype=float), None).reshape(-1, 2)
    rays = np.concatenate([norm, np.ones((norm.shape[0], 1))], axis=1)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    return rays.reshape(np.shape(pixels)[:-1] + (3,))


def localize_by_straight_line(
    pixels: np.ndarray, K: np.ndarray, ground: np.ndarray
) -> StraightLineChoice:
    """pixels (T,3,3,2) [trial, snapshot, robot], K (3,3), ground (T,3,3) robot positions ->
    P3P per snapshot (batched over all T*3) and the straight-line choice."""
    pixels = np.asarray(pixels, dtype=float)
    ground = np.asarray(ground, dtype=float)
    if pixels.ndim != 4 or pixels.shape[1:] != (3, 3, 2):
        raise ValueError(f"localize_by_straight_line: pixels must be (T,3,3,2), got {pixels.shape}")
    if ground.shape != (pixels.shape[0], 3, 3):
        raise ValueError(
            f"localize_by_straight_line: ground must be ({pixels.shape[0]},3,3), got {ground.shape}"
        )
    T = pixels.shape[0]
    bearings = bearings_from_pixels(pixels, K).reshape(T * 3, 3, 3)
    points = np.repeat(ground, 3, axis=0)
    cands = solve_p3p(bearings, points)
    pos = cands.t_wc.reshape(T, 3, MAX_CANDIDATES, 3)
    valid = cands.valid.reshape(T, 3, MAX_CANDIDATES)
    chosen, error, second, errors = pick_straight_line(pos, valid)
    return StraightLineChoice(
        errors=errors,
        chosen=chosen,
        error=error,
        second_error=second,
        found=np.isfinite(error),
        candidates=cands,
    )


@config_dataclass
class StraightLineConfig:
    """spacing: updates between the three snapshots; max_error [m]: commit when the best
    combination's line error is below this (seed 000 sec. VI-A step 5 uses 0.003 m)."""

    spacing: int = setting(10, ge=1)
    max_error: float = setting(0.003, gt=0.0)


class StraightLineBaseline:
    """update(candidates, odometry) -> Decision, the same interface as HypothesisTracker. From
    update 2*spacing on, the current frame and the frames spacing and 2*spacing updates earlier
    are the three snapshots; the best combination commits its current-frame candidate when its
    line error is below max_error. Odometry is validated but not used (the seed's test needs
    none)."""

    def __init__(self, config: StraightLineConfig = StraightLineConfig()):
        self.config = config
        self._history: list[CandidateSet] = []
        self._last_time: float | None = None
        self._locked = False

    def update(self, candidates: CandidateSet, odometry=None):
        check_frame(
            candidates,
            odometry,
            self._last_time is None,
            self._last_time,
            "StraightLineBaseline.update",
        )
        self._last_time = candidates.time
        s = int(self.config.spacing)
        self._history = (self._history + [candidates])[-(2 * s + 1) :]
        K = len(candidates)
        probs = np.full(K, 1.0 / K) if K else np.zeros(0)
        was_locked, self._locked = self._locked, False
        if len(self._history) < 2 * s + 1 or K == 0:
            pose = candidates.poses()[0] if K else None
            return Decision(probs, -1, False, pose, relocalized=was_locked)
        frames = (self._history[0], self._history[s], self._history[-1])
        kmax = max(len(f) for f in frames)
        pos = np.zeros((1, 3, kmax, 3))
        valid = np.zeros((1, 3, kmax), bool)
        for i, f in enumerate(frames):
            pos[0, i, : len(f)] = f.t
            valid[0, i, : len(f)] = True
        chosen, error, _, _ = pick_straight_line(pos, valid)
        best = int(chosen[0, 2]) if np.isfinite(error[0]) else 0
        self._locked = bool(error[0] < self.config.max_error)
        probs = np.zeros(K)
        probs[best] = 1.0
        pose = candidates.poses()[best]
        return Decision(
            probs,
            best if self._locked else -1,
            self._locked,
            pose,
            relocalized=was_locked and not self._locked,
        )
