"""Marker pixels -> candidate poses: the one route from a camera's view of a marker layout to
a `CandidateSet` with a first-order covariance per candidate (`resection_covariance`); poses are
the camera in the layout's frame (target_T_camera).
- Distinct markers (seed 000 Sec. III-B, seed 004 Sec. II-A): P3P on three of them, every frame
  in one batched call; with four or more, every candidate (and SQPnP's minimum) refined on all
  pixels and gated by its reprojection chi-square at `GATE_PROBABILITY`, a frame no candidate
  passes an empty, inconsistent set (docs/design_algorithms.md, "Marker poses").
- Identical markers (seed 001 Sec. IV-C): `graphloc.vision.target.target_hypotheses_frames`.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.stats import chi2 as chi2_distribution

from graphloc.candidates import CandidateSet
from graphloc.geometry.p3p import solve_p3p
from graphloc.geometry.resection import resection_covariance
from graphloc.vision.target import MarkerTarget, TargetHypothesisConfig, target_hypotheses_frames

GATE_PROBABILITY = 0.999  # a candidate whose pixel chi-square exceeds this quantile is refused
SAME_POSE_RAD, SAME_POSE_REL = 1e-4, 1e-4  # refinements this close (rad; m per m of range) merge
REFINE_REACH = 25.0  # P3P candidates within this many gates of chi-square are refined


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
        px_all = [np.asarray(p, dtype=float) for p in pixels]
        frames = [i for i in range(n) if len(px_all[i]) in (3, 4) and len(layout) == 4]
        sets = target_hypotheses_frames(
            [px_all[i] for i in frames],
            camera,
            target,
            config,
            times=[float(times[i]) for i in frames],
            observer=observer,
            observed=observed,
        )
        found = [(i, cs) for i, cs in zip(frames, sets) if len(cs)]
        if found:  # every frame's candidates through one covariance call
            used = [
                np.argsort(cs.meta["assignment"] < 0, axis=1, kind="stable")[:, :3]
                for _, cs in found
            ]
            cov = resection_covariance(
                camera,
                np.concatenate([cs.R for _, cs in found]),
                np.concatenate([cs.t for _, cs in found]),
                layout[np.concatenate(used)],
                pixel_sigma,
            )
            splits = np.cumsum([len(cs) for _, cs in found])[:-1]
            for (i, cs), c in zip(found, np.split(cov, splits)):
                out[i] = _with(cs, c, truth_t, i)
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
    found: dict = {}  # markers fitted -> [(frame, its set without covariances, their points)]
    for i in np.flatnonzero(ok):
        keep = sol.valid[i]
        R, t = sol.R_wc[i][keep], sol.t_wc[i][keep]
        markers = first3[i].tolist()
        points = np.broadcast_to(layout[first3[i]], (len(R), 3, 3))
        meta: dict = {}
        if len(px_all[i]) > 3:  # every pixel judges every candidate (module docstring)
            markers = ids_all[i][order[i]].tolist()
            pts, uv = layout[markers], px_all[i][order[i]]
            dof = 2 * len(pts) - 6
            gate = float(chi2_distribution.ppf(GATE_PROBABILITY, dof))
            reach = REFINE_REACH * gate * pixel_sigma**2
            R, t, chi2 = refine_on_all_points(camera, R, t, pts, uv, reach)
            scaled = chi2 / max(pixel_sigma, 1e-6) ** 2
            meta = {"chi2": scaled.tolist(), "dof": dof, "gate": gate}
            passing = scaled <= gate
            if not passing.any():
                meta.update(inconsistent=True, chi2_min=float(scaled.min(initial=np.inf)))
            R, t, scaled = R[passing], t[passing], scaled[passing]
            meta["chi2"] = scaled.tolist()
            scores = np.exp(-0.5 * scaled)
            points = np.broadcast_to(pts, (len(R),) + pts.shape)
        else:
            scores = np.exp(-0.5 * (sol.residual[i][keep] / 1e-3) ** 2)
        cs = CandidateSet(
            R,
            t,
            scores,
            time=float(times[i]),
            observer=observer,
            observed=observed,
            source=f"p3p/{sol.method}",
            meta={"markers": markers, **meta},
        )
        found.setdefault(points.shape[1], []).append((i, cs, points))
    # the covariances of every frame's candidates fitted to as many markers in one call
    for group in found.values():
        cov = resection_covariance(
            camera,
            np.concatenate([cs.R for _, cs, _ in group]),
            np.concatenate([cs.t for _, cs, _ in group]),
            np.concatenate([points for _, _, points in group]),
            pixel_sigma,
        )
        splits = np.cumsum([len(cs) for _, cs, _ in group])[:-1]
        for (i, cs, _), c in zip(group, np.split(cov, splits)):
            out[i] = _with(cs, c, truth_t, i)
    return out


def refine_on_all_points(
    camera,
    R_wc: np.ndarray,
    t_wc: np.ndarray,
    points: np.ndarray,
    pixels: np.ndarray,
    reach: float = np.inf,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera poses (K,3,3)/(K,3) in the points' frame and SQPnP's global minimum on all M
    points (M,3) seen at `pixels` (M,2) (`cv2.SOLVEPNP_SQPNP`), each refined by
    Levenberg-Marquardt on all points (`cv2.solvePnPRefineLM`, distortion included) when its
    sum of squared pixel residuals is within `reach` (SQPnP's always: a start farther off than
    that cannot end in a pose the gate passes other than the global minimum); refinements that
    land on one pose merged. Returns (R_wc (J,3,3), t_wc (J,3), sum of squared pixel residuals
    (J,)) sorted by that sum; a pose with a point behind the camera gets inf."""
    K, dist = camera.K, np.asarray(camera.dist, dtype=float)
    obj = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 1, 3)
    img = np.ascontiguousarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
    R_wc, t_wc = np.asarray(R_wc, float).reshape(-1, 3, 3), np.asarray(t_wc, float).reshape(-1, 3)
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_SQPNP)
    except cv2.error:  # a degenerate point set: the P3P candidates remain
        ok = False
    if ok:
        R_cw = cv2.Rodrigues(rvec)[0]
        R_wc = np.concatenate([[R_cw.T], R_wc])
        t_wc = np.concatenate([[-R_cw.T @ tvec.reshape(3)], t_wc])
    cost = _reprojection_cost(camera, R_wc, t_wc, points, pixels)
    out_R, out_t, out_c = [], [], []
    for j, (Rw, tw) in enumerate(zip(R_wc, t_wc)):
        if (ok and j == 0) or cost[j] <= reach:
            rvec, tvec = cv2.solvePnPRefineLM(
                obj, img, K, dist, cv2.Rodrigues(Rw.T)[0], (-Rw.T @ tw).reshape(3, 1)
            )
            R_cw = cv2.Rodrigues(rvec)[0]
            Rw, tw = R_cw.T, -R_cw.T @ tvec.reshape(3)
            c = float(_reprojection_cost(camera, Rw[None], tw[None], points, pixels)[0])
        else:
            c = float(cost[j])
        scale = max(float(np.linalg.norm(points - tw, axis=1).max()), 1e-9)
        same = next(
            (
                i
                for i in range(len(out_R))
                if np.linalg.norm(cv2.Rodrigues(out_R[i].T @ Rw)[0]) < SAME_POSE_RAD
                and np.linalg.norm(out_t[i] - tw) < SAME_POSE_REL * scale
            ),
            None,
        )
        if same is None:
            out_R.append(Rw), out_t.append(tw), out_c.append(c)
        elif c < out_c[same]:
            out_R[same], out_t[same], out_c[same] = Rw, tw, c
    order = np.argsort(out_c, kind="stable")
    return (
        np.array(out_R).reshape(-1, 3, 3)[order],
        np.array(out_t).reshape(-1, 3)[order],
        np.array(out_c, dtype=float)[order],
    )


def _reprojection_cost(camera, R_wc, t_wc, points, pixels) -> np.ndarray:
    """Sum of squared pixel residuals (K,) of camera poses (K,3,3)/(K,3) seeing points (M,3)
    at pixels (M,2); inf where a point is behind the camera or does not project."""
    pc = np.einsum("kji,kmj->kmi", R_wc, points[None] - t_wc[:, None])
    proj, _ = camera.project(pc.reshape(-1, 3))
    err = np.sum((proj.reshape(len(R_wc), -1, 2) - pixels[None]) ** 2, axis=(1, 2))
    behind = (pc[..., 2] <= 0).any(axis=1)
    return np.where(np.isfinite(err) & ~behind, err, np.inf)


def _with(cs: CandidateSet, cov: np.ndarray, truth_t, i: int) -> CandidateSet:
    meta = dict(cs.meta)
    if truth_t is not None and len(cs):
        d = np.linalg.norm(cs.t - truth_t[i], axis=1)
        meta.update(genuine=int(np.argmin(d)), genuine_error=float(d.min()))
    return CandidateSet(
        cs.R, cs.t, cs.scores, cs.time, cs.observer, cs.observed, cs.source, meta, cov
    )
