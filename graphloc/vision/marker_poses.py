"""Marker pixels -> candidate poses: the one route from a camera's view of a marker layout to
a `CandidateSet` with a first-order covariance per candidate.

- Distinct markers (seed 000 Sec. III-B, seed 004 Sec. II-A: three robots / three LEDs): P3P on
  three of them (`graphloc.geometry.p3p.solve_p3p`, every frame of a run in one batched call),
  up to 4 candidates; further markers score each candidate by their reprojection error
  (score = exp(-rms^2 / 2 sigma^2)); with exactly three markers every candidate fits exactly and
  the scores are ~1 (seed 000 Sec. V-A: belief 1/4 each).
- Identical markers (seed 001 Sec. IV-C): the 24 x 4 P3P hypotheses of four blobs gated by the
  fourth marker (`graphloc.vision.target.target_hypotheses`).
Covariance: `graphloc.geometry.resection.resection_covariance` (pixel noise through the P3P
pose, on the three markers P3P used).
Poses are the camera in the layout's frame (target_T_camera).
"""

from __future__ import annotations

import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.geometry.p3p import solve_p3p
from graphloc.geometry.resection import resection_covariance
from graphloc.vision.target import MarkerTarget, TargetHypothesisConfig, target_hypotheses


def p3p_candidate_sets(
    camera,
    pixels: list,
    marker_ids: list,
    layout: np.ndarray,
    times,
    pixel_sigma: float,
    identical: bool = False,
    observer: str = "",
    observed: str = "",
    truth_t: np.ndarray | None = None,
) -> list:
    """One CandidateSet per frame i (empty when no pose fits, None when a pixel has no bearing
    or too few markers were seen): pixels[i] (n_i,2) of markers
    marker_ids[i] (n_i,) of `layout` (m,3); n_i >= 3 (4 for identical markers). With
    truth_t (frames,3) (simulations), meta["genuine"] is the candidate nearest the true camera
    position and meta["genuine_error"] its distance [m]."""
    layout = np.asarray(layout, dtype=float)
    if layout.ndim != 2 or layout.shape[1] != 3 or len(layout) < 3:
        raise ValueError(f"p3p_candidate_sets: layout must be (m>=3, 3), got {layout.shape}")
    if not (np.isfinite(pixel_sigma) and pixel_sigma >= 0):
        raise ValueError(f"p3p_candidate_sets: pixel_sigma must be finite >= 0, got {pixel_sigma}")
    n = len(pixels)
    out: list = [None] * n
    if identical:
        target = MarkerTarget(layout, 0.01, "layout")
        config = TargetHypothesisConfig(pixel_sigma=max(pixel_sigma, 0.5))
        for i in range(n):
            px = np.asarray(pixels[i], dtype=float)
            if len(px) not in (3, 4) or len(layout) != 4:
                continue
            cs = target_hypotheses(
                px,
                camera,
                target,
                config,
                time=float(times[i]),
                observer=observer,
                observed=observed,
            )
            if len(cs):
                assign = cs.meta["assignment"]
                used = np.argsort(assign < 0, axis=1, kind="stable")[:, :3]
                cov = resection_covariance(camera, cs.R, cs.t, layout[used], pixel_sigma)
                out[i] = _with(cs, cov, truth_t, i)
        return out
    px_all = [np.asarray(p, dtype=float).reshape(-1, 2) for p in pixels]
    if any(len(p) < 3 for p in px_all):
        raise ValueError("p3p_candidate_sets: every frame needs at least 3 marker pixels")
    ids_all = [np.asarray(m, dtype=int) for m in marker_ids]
    order = [np.argsort(m, kind="stable") for m in ids_all]
    first3 = np.array([m[o[:3]] for m, o in zip(ids_all, order)])  # (n,3) markers P3P uses
    px3 = np.array([p[o[:3]] for p, o in zip(px_all, order)])  # (n,3,2)
    bearings, ok = camera.pixel_to_bearing(px3.reshape(-1, 2))
    ok = ok.reshape(n, 3).all(axis=1)
    sol = solve_p3p(
        np.where(ok[:, None, None], bearings.reshape(n, 3, 3), [[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
        layout[first3],
    )
    for i in np.flatnonzero(ok):
        keep = sol.valid[i]
        R, t = sol.R_wc[i][keep], sol.t_wc[i][keep]
        extra = order[i][3:]
        if extra.size and len(R):  # markers beyond three score the candidates
            pts = layout[ids_all[i][extra]]
            proj, front = camera.project(
                np.einsum("kji,kpj->kpi", R, pts[None] - t[:, None]).reshape(-1, 3)
            )
            err = np.linalg.norm(proj.reshape(len(R), -1, 2) - px_all[i][extra][None], axis=2)
            err = np.where(front.reshape(len(R), -1), err, np.inf)
            rms = np.sqrt(np.mean(err**2, axis=1))
            scores = np.exp(-0.5 * (rms / max(pixel_sigma, 1e-6)) ** 2)
        else:
            scores = np.exp(-0.5 * (sol.residual[i][keep] / 1e-3) ** 2)
        cov = resection_covariance(
            camera, R, t, np.broadcast_to(layout[first3[i]], (len(R), 3, 3)), pixel_sigma
        )
        cs = CandidateSet(
            R,
            t,
            scores,
            time=float(times[i]),
            observer=observer,
            observed=observed,
            source=f"p3p/{sol.method}",
            meta={"markers": first3[i].tolist()},
        )
        out[i] = _with(cs, cov, truth_t, i)
    return out


def _with(cs: CandidateSet, cov: np.ndarray, truth_t, i: int) -> CandidateSet:
    meta = dict(cs.meta)
    if truth_t is not None and len(cs):
        d = np.linalg.norm(cs.t - truth_t[i], axis=1)
        meta.update(genuine=int(np.argmin(d)), genuine_error=float(d.min()))
    return CandidateSet(
        cs.R, cs.t, cs.scores, cs.time, cs.observer, cs.observed, cs.source, meta, cov
    )
