"""When a hypothesis method locks onto a candidate, and whether rightly: the per-run statistics of
seed 000 Table III (Sec. VI-B) shared by the engines' trials (`benchmarks.hypotheses`)
and the front door's (`benchmarks.front_door`)."""

from __future__ import annotations

import numpy as np


def lock_statistics(frames) -> dict:
    """frames: per update k (in order) a tuple (k, locked, ok, err2, relocalized): the method is
    locked at k, its lock is right, the squared distance of its pose to the truth, it
    relocalized. Returns converged / correct_lock (k of the first lock / first right lock, None
    if never), wrong (the first lock is not right), locked_frames, wrong_locked_frames,
    relocalizations, rmse_locked and median_error_locked (over the locked frames)."""
    converged = correct_lock = None
    wrong = False
    locked = wrong_frames = relocalizations = 0
    sq = []
    for k, is_locked, ok, err2, relocalized in frames:
        relocalizations += int(relocalized)
        if not is_locked:
            continue
        locked += 1
        wrong_frames += int(not ok)
        sq.append(err2)
        if ok and correct_lock is None:
            correct_lock = k
        if converged is None:
            converged, wrong = k, not ok
    return {
        "converged": converged,
        "wrong": bool(wrong),
        "correct_lock": correct_lock,
        "relocalizations": relocalizations,
        "locked_frames": locked,
        "wrong_locked_frames": wrong_frames,
        "rmse_locked": float(np.sqrt(np.mean(sq))) if sq else None,
        "median_error_locked": float(np.sqrt(np.median(sq))) if sq else None,
    }
