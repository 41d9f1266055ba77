"""Inter-robot scan registration (seed 004 Sec. II-C / III) as a scan-matching factor:
`register_pair` aligns one robot's scan onto another's from a hint and its covariance
(`mapping.robust_registration.robust_register`); a rejected one is counted, never guessed."""

from __future__ import annotations


import gtsam

from graphloc.keys import pose_key
from graphloc.pipelines.team_graph.config import adjoint_cov
from graphloc.pipelines.team_graph.motion import compose_steps
from graphloc.run import TeamRun


def scan_near(run: TeamRun, r: int, t: float):
    scans = [s for s in run.scans if s.robot == r]
    return min(scans, key=lambda s: abs(s.time - t)) if scans else None


def register_pair(run, config, timeline, step_rel, poses, guess, a, b, skips, reasons, prepared):
    """Robot b's scan nearest its guess (node, time, body pose, 6x6 covariance) registered onto
    robot a's scan at the same time: (factor time, factor, {b's node: (a, a's node, rel)},
    (scan times)) or None (counted). `prepared`: scan path -> PreparedCloud, the scans this
    section has prepared (filled here)."""
    nearest, node_times = timeline.nearest, timeline.node_times
    k_tent, t_tent, X_tent, cov_tent = guess
    scan_b = scan_near(run, b, t_tent)
    scan_a = scan_near(run, a, scan_b.time)
    name = f"robots {run.robots[a].name} / {run.robots[b].name}"
    if abs(scan_a.time - scan_b.time) > max(config.sync_tolerance, config.keyframe_dt / 2):
        skips.add("scan_match_rejected", f"{name}: no scans at a common time near {t_tent}")
        return None
    ka, kb = nearest(a, scan_a.time), nearest(b, scan_b.time)
    if ka < 0 or kb < 0:
        skips.add("no_pose_at_time", f"{name}: scans at {scan_b.time} have no poses")
        return None
    if kb >= k_tent:
        step, step_cov = compose_steps(step_rel[b], k_tent, kb, config)
    else:
        back, step_cov = compose_steps(step_rel[b], kb, k_tent, config)
        step = back.inverse()
    X_b = X_tent.compose(step)
    cov_b = adjoint_cov(step.inverse(), cov_tent) + step_cov
    E_a, E_b = scan_a.body_T_sensor, scan_b.body_T_sensor
    hint = poses[a][0][ka].compose(E_a).inverse().compose(X_b.compose(E_b))  # T_sa_sb
    hint_cov = adjoint_cov(E_b.inverse(), cov_b)
    # Open3D loads only for runs that register scans (`graphloc smooth` of other runs skips it)
    from graphloc.mapping.io import read_scan
    from graphloc.mapping.acceptance import AcceptanceConfig
    from graphloc.mapping.registration import RegistrationConfig, prepare
    from graphloc.mapping.robust_registration import robust_register

    cfg = config.registration or RegistrationConfig()
    acceptance = config.acceptance or AcceptanceConfig()
    try:
        # the scans as the reader kept them (thinned to the point budget, read again quietly)
        for scan in (scan_b, scan_a):
            if scan.path not in prepared:
                prepared[scan.path] = prepare(read_scan(scan.path, warn=False)[0], cfg)
        source, target = prepared[scan_b.path], prepared[scan_a.path]
    except (OSError, ValueError) as exc:
        raise ValueError(f"{name}: scan registration: {exc}") from None
    decision = robust_register(
        source, target, hint.matrix(), 0.5 * (hint_cov + hint_cov.T), cfg, acceptance
    )
    if not decision.accepted:
        reasons.append(
            f"{name}: scans at {scan_b.time}: registration not accepted "
            f"({'; '.join(decision.reasons)})"
        )
        return None
    T = gtsam.Pose3(decision.registration.transformation)  # T_sa_sb
    rel = E_a.compose(T).compose(E_b.inverse())  # body_a_T_body_b
    cov = adjoint_cov(E_b, decision.covariance)
    noise = gtsam.noiseModel.Gaussian.Covariance(0.5 * (cov + cov.T))
    factor = gtsam.BetweenFactorPose3(pose_key(a, ka), pose_key(b, kb), rel, noise)
    t = max(node_times[a][ka], node_times[b][kb], t_tent)
    return t, factor, {kb: (a, ka, rel)}, (scan_a.time, scan_b.time)
