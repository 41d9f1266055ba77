"""Inter-robot scan registration (seed 004 Sec. II-C / III: P3P initializes ICP, which fuses the
ground and ceiling robots' maps) as a scan-matching factor of the team graph.

For each pair of robots that both scan, one placed and one not: the unplaced robot's pose hint
is the candidate tracker's latest best guess of it (committed or not: P3P's up to four
candidates over a few frames may not commit, and the scans can tell them apart), carried by its
odometry to its scan nearest that guess; `graphloc.mapping.robust_registration.robust_register`
aligns that scan onto the placed robot's scan taken at the same time, starting from the hint and
its covariance, with the acceptance checks (overlap, inliers, hint gate, geometry). An accepted
registration becomes a BetweenFactorPose3 between the two robots' poses with the registration's
calibrated covariance, and places the unplaced robot; a rejected one is counted (reason
`scan_match_rejected`, with the failed checks), never guessed."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
from tqdm import tqdm

from graphloc.keys import pose_key
from graphloc.pipelines.team_graph.config import GraphConfig, adjoint_cov, cov6
from graphloc.pipelines.team_graph.motion import Timeline, compose_steps, place_robot
from graphloc.pipelines.team_graph.section import SectionFactors
from graphloc.run import TeamRun


@dataclass
class ScanSection:
    """The scan section's output: the accepted registrations ((time, factor, 'scan_match')
    each) and the rejections (`made`), and the robots they place (robot -> {node: (placed
    robot, its node, body_T_body)})."""

    made: SectionFactors
    placed_via: dict


def scan_match_factors(
    run: TeamRun,
    config: GraphConfig,
    timeline: Timeline,
    step_rel: list,
    poses: dict,
    tentative: dict,
    progress: bool = False,
) -> ScanSection:
    """Register every unplaced scanning robot with a tentative pose onto a placed scanning
    robot (`poses`: robot -> ([initial Pose3 per node], first seeded node) of the placed
    robots), from each of its hypotheses in turn (`tentative`: the tracker's guess, then the
    last set's candidates) until one is accepted, then every further common scan time of two
    placed robots; a robot whose every registration is rejected stays unplaced (counted)."""
    made = SectionFactors()
    factors, skips = made.factors, made.skips
    placed_via: dict = {}
    poses = dict(poses)  # a robot placed here joins the placed ones for the scans after it
    scanning = sorted({s.robot for s in run.scans})
    if len(scanning) < 2 or not any(b in poses or b in tentative for b in scanning):
        return ScanSection(made, placed_via)
    used = set()
    prepared: dict = {}  # scan path -> its PreparedCloud: each scan prepared once
    for b in scanning:
        if b in poses or b not in tentative:
            continue
        reasons = []
        for a in (a for a in scanning if a in poses):
            for guess in tentative[b]:  # the tracker's guess, then each candidate
                link = register_pair(
                    run, config, timeline, step_rel, poses, guess, a, b, skips, reasons, prepared
                )
                if link is not None:
                    break
            if link is not None:
                t, factor, via, stamps = link
                factors.append((t, factor, "scan_match"))
                placed_via[b] = via
                used.add(stamps)
                poses[b] = place_robot(
                    run, b, timeline.node_times, step_rel, config, {}, {b: via}, poses
                )
                break
        if b not in placed_via and reasons:
            skips.add(
                "scan_match_rejected",
                f"robot {run.robots[b].name}: no registration from its {len(tentative[b])} "
                f"hypotheses was accepted ({reasons[0]}); left unplaced",
            )
    # every further common scan time of two placed robots, from the current initial poses
    placed = [r for r in scanning if r in poses]
    for i, a in enumerate(placed):
        for b in placed[i + 1 :]:
            scans_b = [s for s in run.scans if s.robot == b]
            desc = f"registering {run.robots[b].name} onto {run.robots[a].name}"
            for scan_b in tqdm(scans_b, desc=desc, disable=not progress, unit="scan"):
                kb = timeline.nearest(b, scan_b.time)
                if kb < 0:
                    continue
                scan_a = scan_near(run, a, scan_b.time)
                if (scan_a.time, scan_b.time) in used:  # the pair placed b: already a factor
                    continue
                guess = (kb, scan_b.time, poses[b][0][kb], cov6(config.scan_hint_sigma))
                reasons = []
                link = register_pair(
                    run, config, timeline, step_rel, poses, guess, a, b, skips, reasons, prepared
                )
                if link is None and reasons:
                    skips.add("scan_match_rejected", reasons[0])
                if link is not None and link[3] not in used:
                    used.add(link[3])
                    factors.append((link[0], link[1], "scan_match"))
    return ScanSection(made, placed_via)  # the caller places those robots through their steps


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
