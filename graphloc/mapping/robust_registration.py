"""The inter-robot registration of issue 16 (seed 004 Sec. IV from a pose hint): a registration
that does not slide on partial overlap, and that says "not fused" instead of returning a
confident wrong answer. `robust_register` runs ICP from the hint and the sigma points of its
covariance (`graphloc.mapping.registration_starts`), keeps the cheapest candidate that passes
the checks of `graphloc.mapping.acceptance`, refines the winner at full resolution (`polish`),
and gives it the covariance of `graphloc.mapping.registration_covariance`.
"""

from __future__ import annotations

import time

import gtsam
import numpy as np
import open3d as o3d

from graphloc.mapping.acceptance import (
    AcceptanceConfig,
    Candidate,
    CHECK_REASONS,
    RegistrationDecision,
    candidate_checks,
    contradicted_fraction,
    cost_margin_se,
    only_slid_or_valid,
    overlap_shortfall,
    point_to_plane,
    residual_scale,
    target_index,
    truncated_costs,
)
from graphloc.mapping.registration import (
    PreparedCloud,
    Registration,
    RegistrationConfig,
    global_fpfh_ransac,
    pose_errors,
    poses_within,
)
from graphloc.mapping.registration_covariance import (
    block_labels,
    calibrated_covariance,
    estimate_covariance,
)
from graphloc.mapping.registration_stages import (
    Polished,
    coarse_clouds,
    fine_stage,
    point_to_plane_estimation,
    polish,
    wide_levels,
)
from graphloc.mapping.registration_starts import (
    checked_hint,
    escape_starts,
    hint_starts,
    weak_direction_starts,
)

reg_l = o3d.pipelines.registration


def robust_register(
    source: PreparedCloud,
    target: PreparedCloud,
    hint: np.ndarray,
    hint_cov: np.ndarray,
    cfg: RegistrationConfig = RegistrationConfig(),
    acc: AcceptanceConfig = AcceptanceConfig(),
) -> RegistrationDecision:
    """Multi-start registration of source onto target around a pose hint (4x4) and its 6x6
    covariance (rot [rad] then trans [m], right perturbation), with acceptance checks: ICP from
    the hint and its sigma points (wide pyramid, coarse, fine stage), a global FPFH start when
    none passes, the re-seat and escape starts of a slid view; the cheapest candidate passing
    `candidate_checks` wins if it undercuts every rival by acc.min_cost_margin_se; the winner is
    polished, checked again at its polished pose (conditioning, covariance caps, overlap
    shortfall, weak-direction probes) and given its calibrated covariance. The steps in full:
    docs/design_algorithms.md, "Robust registration"."""
    start_t = time.perf_counter()
    hint, hint_cov = checked_hint(hint, hint_cov)
    stage_s = dict.fromkeys(("coarse", "fine", "checks", "global", "polish"), 0.0)
    counts = {"starts": 0, "fine_stages": 0, "polish_rounds": 0, "probes": 0, "rivals_polished": 0}

    def timed(stage: str, f, *args):
        t0 = time.perf_counter()
        out = f(*args)
        stage_s[stage] += time.perf_counter() - t0
        return out

    src_c, tgt_c, voxel_c = timed("coarse", coarse_clouds, source, target, cfg)
    fine = cfg.max_correspondence[-1]
    est = point_to_plane_estimation(cfg.coarse_tukey * voxel_c)
    crit_c = reg_l.ICPConvergenceCriteria(1e-6, 1e-6, cfg.max_iterations[0])
    hint_info = np.linalg.inv(0.5 * (hint_cov + hint_cov.T))
    hint_pose = gtsam.Pose3(hint)
    c = residual_scale(source, target, acc)
    # one index for the checks (within `fine`) and the polish's cut (its distance + a voxel)
    nns = target_index(target, max(fine, cfg.polish_distance + cfg.voxel))
    r_med = float(np.median(np.linalg.norm(source.points, axis=1)))
    basin_deg = float(np.degrees(fine / r_med))  # a rotation moving the median point by `fine`
    merged, coarse, cands, iterations, point_costs = {}, [], [], 0, {}
    lam = np.linalg.eigvalsh(hint_cov[:3, :3])[-1], np.linalg.eigvalsh(hint_cov[3:, 3:])[-1]
    reach = min(float(np.sqrt(lam[0]) * r_med + np.sqrt(lam[1])), cfg.max_reach)
    wide = []
    if cfg.coarse_voxels > 0:
        wide = timed("coarse", wide_levels, src_c, tgt_c, reach, cfg.coarse_voxels * voxel_c, cfg)

    def coarse_stage(T0: np.ndarray, tukey: float = cfg.coarse_tukey, levels=wide) -> np.ndarray:
        """The wide pyramid `levels` (while the hint's reach exceeds the coarse one), then the
        coarse ICP."""
        if cfg.coarse_voxels <= 0:
            return T0
        for a, b, dist, voxel in levels:
            est_w = point_to_plane_estimation(tukey * voxel)
            T0 = reg_l.registration_icp(a, b, dist, T0, est_w, crit_c).transformation
        res = reg_l.registration_icp(src_c, tgt_c, cfg.coarse_voxels * voxel_c, T0, est, crit_c)
        return np.asarray(res.transformation)

    # how far (in the hint's Mahalanobis norm) the fine stage can move a pose: one fine basin
    move = (
        np.sqrt(np.linalg.eigvalsh(hint_info[:3, :3])[-1]) * np.radians(basin_deg)
        + np.sqrt(np.linalg.eigvalsh(hint_info[3:, 3:])[-1]) * fine
    )
    min_down = np.cos(np.radians(acc.max_ceiling_tilt_deg + basin_deg))

    def _beyond_fine_reach(T: np.ndarray, k: int) -> str | None:
        """Why a start's coarse pose cannot pass the checks the fine stage hardly changes (the
        hint gate, the robot geometry) after a move of one fine basin; None if it can. The last
        of the hint's own starts gets its fine stage when no earlier start has left a candidate
        (every report holds one of the hint's own); any other hint start that slid beyond the
        gate costs no fine stage."""
        if k == n_hint - 1 and not cands:
            return None
        e = hint_pose.localCoordinates(gtsam.Pose3(T))
        d2 = float(e @ hint_info @ e)
        if np.sqrt(d2) - move > np.sqrt(acc.hint_gate):
            return f"coarse pose beyond the hint gate (Mahalanobis^2 {d2:.1f}), out of fine reach"
        if acc.ceiling_above and (T[2, 3] < -fine or -T[2, 2] < min_down):
            return "coarse pose fails the robot geometry, out of fine reach"
        return None

    def candidate(k: int, T: np.ndarray, residuals=None) -> tuple[Candidate, np.ndarray]:
        """Start k's pose T as a Candidate (cost, overlap, inlier ratio, contradicted cubes, hint
        distance) and its per-point `truncated_costs` (`residuals`: point_to_plane's (r, d, J)
        at T, if already computed)."""
        r, d, _ = residuals if residuals is not None else point_to_plane(source, target, T, nns)
        near = d < fine
        inl = near & (np.abs(r) < c)
        e = hint_pose.localCoordinates(gtsam.Pose3(T))
        ratio = float(inl.sum() / max(near.sum(), 1))
        costs = truncated_costs(r, d, c, fine, acc.misfit_weight)
        cost = float(costs.mean())
        p_near = source.points[near] @ T[:3, :3].T + T[:3, 3]
        bad = contradicted_fraction(p_near, inl[near], acc)
        o = Candidate(k, T, cost, float(inl.mean()), ratio, float(e @ hint_info @ e), bad)
        return o, costs

    def try_start(k: int, T: np.ndarray) -> bool:
        """Fine ICP from one start's coarse pose; True if its candidate passes its own checks."""
        nonlocal iterations
        same = [j for j, Tj in coarse if poses_within(T, Tj, basin_deg, fine)]
        if same:
            merged[k] = f"coarse stage converged within the fine basin of start {same[0]}"
            return False
        hopeless = _beyond_fine_reach(T, k)
        if hopeless:
            merged[k] = hopeless
            return False
        coarse.append((k, T))  # the coarse poses that went on to a fine stage
        try:
            counts["fine_stages"] += 1
            T, n_it = timed("fine", fine_stage, source, target, T, cfg)
        except RuntimeError:  # Open3D: singular 6x6 system, too few correspondences from this start
            merged[k] = f"no correspondences within {fine} m"
            return False
        iterations += n_it
        same = [o.start for o in cands if not _distinct(T, o.transformation, acc)]
        if same:
            merged[k] = f"converged to the pose of start {same[0]}"
            return False
        o, point_costs[k] = timed("checks", candidate, k, T)
        cands.append(o)
        return all(v[2] for v in candidate_checks(cands[-1], acc).values())

    def reseat() -> bool:
        """The re-seat (start len(starts) + 1): the rotation of the cheapest candidate valid or
        only slid (it fails no check but the contradicted cubes) at the hint's translation, no
        pyramid; True if its candidate passes its checks."""
        reseated.append(k_re)
        top = min((o for o in cands if only_slid_or_valid(o, acc)), key=lambda x: x.cost)
        T_re = top.transformation.copy()
        T_re[:3, 3] = hint[:3, 3]
        if poses_within(T_re, top.transformation, basin_deg, fine):
            merged[k_re] = f"hint's translation within the fine basin of start {top.start}"
            return False
        counts["starts"] += 1
        return try_start(k_re, timed("coarse", coarse_stage, T_re, cfg.coarse_tukey, ()))

    # the hint once per wide-level kernel (while there is a wide level), then its sigma points
    tukeys = cfg.hint_wide_tukey if wide else (cfg.coarse_tukey,)
    n_hint, stop, reseated = len(tukeys), cfg.stop_at_first_valid, []
    starts = [(hint, tk) for tk in tukeys]
    starts += [(T, cfg.coarse_tukey) for T in hint_starts(hint, hint_cov)[1:]]
    k_re, found, ready = len(starts) + 1, False, False
    for k, (T0, tk) in enumerate(starts):
        counts["starts"] += 1
        n = len(cands)
        ok = try_start(k, timed("coarse", coarse_stage, T0, tk))
        if stop and not (ok or reseated) and len(cands) > n and only_slid_or_valid(cands[-1], acc):
            ok = reseat()  # a slid view: re-seated at once
        found = ok or found
        ready = ready or (ok and cands[-1].inlier_ratio >= cfg.stop_inlier_ratio)
        if ready and stop:
            break
    if not found and cfg.global_fallback:  # the hint's neighbourhood failed: one global guess
        T_glob, _ = timed("global", global_fpfh_ransac, source, target, cfg, 0)
        counts["starts"] += 1
        found = try_start(len(starts), timed("coarse", coarse_stage, T_glob))
    if not reseated and any(only_slid_or_valid(o, acc) for o in cands):
        reseat()
    # the escape: no candidate passes and one is only slid: from the cheapest such, the hint's
    # reach either way along its least constrained direction (the valley it slid down)
    seats = [o for o in cands if only_slid_or_valid(o, acc)]
    if seats and not any(all(v[2] for v in candidate_checks(o, acc).values()) for o in cands):
        top = min(seats, key=lambda x: x.cost)
        r, d, J = point_to_plane(source, target, top.transformation, nns)
        inl = (d < fine) & (np.abs(r) < c)
        for i, T0 in enumerate(escape_starts(top.transformation, J[inl], r_med, reach)):
            counts["starts"] += 1
            try_start(len(starts) + 2 + i, T0)
    if not cands:
        raise ValueError(
            f"robust_register: no start found correspondences within {fine} m: a wrong "
            "pose hint, or scans that do not overlap"
        )
    checks_of = {o.start: candidate_checks(o, acc) for o in cands}
    valid = [o for o in cands if all(v[2] for v in checks_of[o.start].values())]
    best = min(valid or cands, key=lambda x: x.cost)  # step 3
    lost = dict(merged)
    for o in cands:
        if o.start == best.start or o.start in lost:
            continue
        failed = [k for k, v in checks_of[o.start].items() if not v[2]]
        lost[o.start] = (
            f"failed {', '.join(failed)}"
            if failed
            else f"truncated cost {o.cost:.4f} > {best.cost:.4f} of start {best.start}"
        )
    T = best.transformation
    polished = (  # the cubes count at both poses: no polish mends a winner they refuse
        timed("polish", polish, source, target, T, cfg, nns)
        if checks_of[best.start]["contradicted_fraction"][2]
        else Polished(T, 0, True)
    )
    T = polished.transformation
    counts["polish_rounds"] = polished.rounds
    r, d, J = point_to_plane(source, target, T, nns)
    final, final_costs = candidate(best.start, T, (r, d, J))
    inl = (d < fine) & (np.abs(r) < c)
    n_in = int(inl.sum())
    H = J[inl].T @ J[inl]
    s2 = float(r[inl] @ r[inl]) / max(n_in - 6, 1)
    D = np.diag([r_med**-1] * 3 + [1.0] * 3)
    eig = np.linalg.eigvalsh(D @ H @ D) if n_in >= 6 else np.zeros(6)
    kappa = float(eig[0] / eig[-1]) if eig[-1] > 0 else 0.0  # the conditioning
    # the covariance of the estimate made: the polish's midpoint, else the fine stage's fit
    fit = J[inl], r[inl], (source.points @ T[:3, :3].T + T[:3, 3])[inl]
    terms = None
    if kappa >= acc.min_conditioning:  # else not accepted
        terms = estimate_covariance(polished.views, T, fit, cfg, r_med, acc.min_conditioning)
    cov = np.eye(6) * 1e12 if terms is None else calibrated_covariance(*terms, cfg)
    info = np.linalg.inv(cov)
    checks = dict(candidate_checks(final, acc))  # the polished pose's
    # ... but the contradicted cubes of both poses: a view slid along a wall, which the polish's
    # rounds move on to where the cubes no longer see the slide, stays slid
    seen = max(final.contradicted, best.contradicted)
    checks["contradicted_fraction"] = (seen, acc.max_contradicted, seen <= acc.max_contradicted)
    checks["polish_rounds"] = (polished.rounds, cfg.polish_rounds, polished.settled)
    checks["conditioning"] = (kappa, acc.min_conditioning, kappa >= acc.min_conditioning)
    checks["overlap_shortfall"] = overlap_shortfall(max(best.overlap, final.overlap), cands, acc)
    # step 3's margin: the winner must fit better than every other valid candidate, and than
    # every cheaper one that is only slid (a view that explains the scans better, refused for
    # its contradicted cubes alone, leaves the valid winner one of two wrong poses); one the
    # polish carried the winner to (not distinct from the polished pose) is the same registration
    slid_cheaper = [o for o in cands if o.cost < best.cost and only_slid_or_valid(o, acc)]
    rivals = [o for o in valid if o.start != best.start] + slid_cheaper
    rivals = [o for o in rivals if _distinct(o.transformation, T, acc)]
    label = block_labels(source.points, cfg.margin_block)
    won = point_costs[best.start]
    margins = {o.start: cost_margin_se(won, point_costs[o.start], label) for o in rivals}
    sigma = np.sqrt(np.diag(cov))
    caps = (
        ("sigma_rot_deg", float(np.degrees(sigma[:3].max())), acc.max_sigma_rot_deg),
        ("sigma_trans_m", float(sigma[3:].max()), acc.max_sigma_trans_m),
    )
    for k, v, lim in caps if checks["conditioning"][2] else ():  # degenerate: no covariance
        checks[k] = (v, lim, v <= lim)
    # a rival that denies the margin at the fine stage's poses is polished too, and compared at
    # both polished poses: one the polish brings to the winner's pose is the same registration
    # (only for a fusion every other check accepts)
    for o in rivals if all(v[2] for v in checks.values()) else ():
        if margins[o.start] < acc.min_cost_margin_se:
            P = timed("polish", polish, source, target, o.transformation, cfg, nns).transformation
            counts["rivals_polished"] += 1
            if not _distinct(P, T, acc):
                del margins[o.start]
                lost[o.start] += "; polished to the winner's pose"
            else:
                costs = timed("checks", candidate, o.start, P)[1]
                margins[o.start] = cost_margin_se(final_costs, costs, label)
    # a polish that carried the view beyond the fine stage's reach left the poses the starts
    # explored: polish again from as far either way along the covariance's weakest direction; a
    # distinct pose found there is one more rival of the margin (only for an accepted fusion)
    passed = all(v[2] for v in checks.values()) and (
        not margins or min(margins.values()) >= acc.min_cost_margin_se
    )
    moved = pose_errors(best.transformation, T)[1]  # how far the polish carried the sensor
    if passed and moved > fine:
        for i, T0 in enumerate(weak_direction_starts(T, cov, r_med, moved)):
            k = len(starts) + 4 + i
            counts["probes"] += 1
            P = timed("polish", polish, source, target, T0, cfg, nns).transformation
            if not _distinct(P, T, acc):
                lost[k] = "weak-direction probe: polished back to the winner's pose"
                continue
            o, costs = timed("checks", candidate, k, P)
            cands.append(o)
            failed = [n for n, v in candidate_checks(o, acc).items() if not v[2]]
            lost[k] = f"weak-direction probe: truncated cost {o.cost:.4f} vs {final.cost:.4f}" + (
                f", failed {', '.join(failed)}" if failed else ""
            )
            if not failed or (o.cost < final.cost and failed == ["contradicted_fraction"]):
                margins[k] = cost_margin_se(final_costs, costs, label)
    if margins:
        m = min(margins.values())
        checks["cost_margin_se"] = (m, acc.min_cost_margin_se, m >= acc.min_cost_margin_se)
    reasons = tuple(
        f"{CHECK_REASONS[k]} ({k} {v[0]:.4g} vs {v[1]:.4g})" for k, v in checks.items() if not v[2]
    )
    seconds = time.perf_counter() - start_t
    reg = Registration(T, final.overlap, float(np.sqrt(s2)), iterations, info, seconds)
    timings = {f"{k}_s": v for k, v in stage_s.items()}
    timings["rest_s"] = seconds - sum(stage_s.values())  # final checks, covariance, bookkeeping
    args = (checks, tuple(cands), best.start, lost, cov, seconds, dict(timings, **counts), c)
    return RegistrationDecision(reg, not reasons, reasons, *args, covariance_terms=terms)


def _distinct(A: np.ndarray, B: np.ndarray, acc: AcceptanceConfig) -> bool:
    return not poses_within(A, B, acc.distinct_deg, acc.distinct_m)
