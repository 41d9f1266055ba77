"""`build_graph`: a `TeamRun` -> `TeamGraph`, every factor grouped in time steps with initial
values (the sections: `motion`, `points`, `candidates`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np

from graphloc.io import SkipReport
from graphloc.keys import decode, pose_key
from graphloc.factors.mixture import MaxMixture
from graphloc.pipelines.team_graph.camera import feature_factors
from graphloc.pipelines.team_graph.candidates import candidate_section
from graphloc.pipelines.team_graph.config import COARSE_PRECISION, GraphConfig, run_precision
from graphloc.pipelines.team_graph.formation import place_unplaced
from graphloc.pipelines.team_graph.motion import (
    Timeline,
    anchor_factors,
    motion_factors,
    place_robot,
)
from graphloc.pipelines.team_graph.points import point_factors
from graphloc.pipelines.team_graph.scans import scan_match_factors
from graphloc.run import TeamRun


@dataclass
class TeamGraph:
    """The run as one graph, step by step: steps[i] = (time, [(factor, type), ...]); node
    times per robot; dead-reckoning / decided initial values; factor type counts."""

    run: TeamRun
    config: GraphConfig
    node_times: list
    initial: dict  # key -> Pose3 (initial guess)
    steps: list
    factor_types: list
    decisions: list
    anchored_from: dict  # robot -> first node time the online graph may hold it
    step_rel: (
        list  # per robot (relative Pose3 from node k-1, covariance) for k >= 1 (None: unknown)
    )
    counts: dict = field(default_factory=dict)
    skips: SkipReport = field(default_factory=SkipReport)
    precision: float = COARSE_PRECISION  # run_precision(run)
    links: dict = field(default_factory=dict)  # observer pose key -> (target key, (K,4,4))
    # other initial values the batch solve starts from too (key -> value, over `initial`): one
    # per candidate of a pixel stream's first set (`candidates.place_observers`) or of a
    # resected robot's first sets (`formation.place_unplaced`)
    alternatives: list = field(default_factory=list)
    # those of robots placed by the tracker's guess (it never decided their stream): the online
    # solve starts from these too
    guessed_alternatives: list = field(default_factory=list)
    # a moving target's marker point of one set -> (the target's pose key, its body-frame
    # position): online predicts the point from the pose's estimate
    frame_points: dict = field(default_factory=dict)
    # an offset sensor's pose variable -> (its body pose key, body_T_sensor): its value is the
    # body pose's composed with the extrinsics (`points.SensorPoses`)
    sensor_poses: dict = field(default_factory=dict)
    # the graph holds feature tracks or max-mixtures (iSAM2's settings for camera graphs,
    # `passes.camera_graph`); a graph built live knows it from the run's tables before its rows
    camera: bool = False
    # the time of the node each alternative (each guessed alternative) was placed at: the
    # node of its own candidate set; the solve does not drop a hypothesis before that node's
    # step (`side_by_side.SideBySide`): earlier steps hold another snapshot's pose, which its start
    # only carried along
    alternative_times: list = field(default_factory=list)
    guessed_alternative_times: list = field(default_factory=list)


def build_graph(
    run: TeamRun, config: GraphConfig = GraphConfig(), progress: bool = False
) -> TeamGraph:
    """Every usable row of `run` as a factor, grouped in time steps, with initial values: the
    sections (`motion`, `points`, `camera`, `candidates`, `formation`, `scans`), each returning
    what it makes, then `initial_poses`, `initial_values`, `alternative_starts` and
    `time_steps`."""
    skips = SkipReport()
    skips.merge(run.skips)
    timeline = Timeline(run, config)
    node_times = timeline.node_times
    motion = motion_factors(run, config, timeline)
    step_rel = motion.step_rel
    points = point_factors(run, config, timeline)
    features = feature_factors(run, config, timeline)
    sets = candidate_section(run, config, timeline, step_rel, progress)
    by_bearings = place_unplaced(run, timeline, sets.decided_pose, sets.placed_via)
    # (time of newest node, factor, type), in the sections' order
    factors = motion.made.factors + anchor_factors(run, config, node_times)
    factors += points.made.factors + features.made.factors + sets.factors
    for section in (motion.made.skips, points.made.skips, features.made.skips, sets.skips):
        skips.merge(section)
    decided_pose = {**sets.decided_pose, **by_bearings.poses}
    poses = initial_poses(run, config, timeline, step_rel, decided_pose, sets.placed_via)
    # a robot a pixel stream placed only by the tracker's guess (never decided) is registered
    # from its hypotheses like an unplaced one: the guess at the stream's first set may be the
    # wrong candidate, and scans from it never meet (dual-robot-room: the ceiling robot)
    guessed = {r for r, (_, g) in sets.alternatives.items() if g and r in sets.tentative}
    scans = scan_match_factors(
        run,
        config,
        timeline,
        step_rel,
        {r: p for r, p in poses.items() if r not in guessed},
        sets.tentative,
        progress,
    )
    factors += scans.made.factors
    skips.merge(scans.made.skips)
    for r in scans.placed_via:
        poses[r] = place_robot(run, r, node_times, step_rel, config, {}, scans.placed_via, poses)
    skips.merge(unplaced_robots(run, node_times, poses))
    landmark_guess = {**points.landmark_guess, **features.landmark_guess}
    sensor_poses = points.sensor_poses
    initial = initial_values(poses, landmark_guess, sets.marker_points, sets.frame_points)
    with_sensors(initial, sensor_poses)
    alternatives = {**sets.alternatives, **by_bearings.alternatives}
    variants, guessed_variants = alternative_starts(
        run, config, timeline, step_rel, poses, alternatives, sensor_poses
    )
    for lkey, sigma, t in features.point_priors:
        if lkey in initial:
            noise = gtsam.noiseModel.Isotropic.Sigma(3, sigma)
            factors.append(
                (t, gtsam.PriorFactorPoint3(lkey, initial[lkey], noise), "feature_prior")
            )
    steps, types, dropped = time_steps(factors, initial)
    if dropped:
        skips.add(
            "unanchored_robot",
            f"{dropped} factors touch poses of robots that nothing places",
            dropped,
        )
    decisions = sets.decisions
    counts = {
        "robots": len(run.robots),
        "poses": len([k for k in initial if decode(k)[0] == "x"]),
        "candidate_sets": len(run.observations),
        "marker_points": len(sets.marker_points),
        "frame_marker_points": len(sets.frame_points),
        "sensor_poses": len(sensor_poses),
        "committed_sets": sum(d.committed >= 0 for d in decisions),
        "landmark_anchors": points.n_anchor,
        "feature_tracks": features.tracks,
        "steps": len(steps),
        "excluded_by_option": points.excluded,
        **{f"factors_{name}": types.count(name) for name in sorted(set(types))},
    }
    return TeamGraph(
        run,
        config,
        node_times,
        initial,
        steps,
        types,
        decisions,
        {r: node_times[r][poses[r][1]] for r in sorted(poses)},
        step_rel,
        counts,
        skips,
        run_precision(run),
        {
            d.mixture.components[0][0].keys()[0]: (
                d.mixture.components[0][0].keys()[1],
                d.relative,
            )
            for d in decisions
            if d.mixture is not None and d.relative is not None
        },
        variants,
        guessed_variants,
        {key: (pose_key(ti, kt), local) for key, ti, kt, local in sets.frame_points},
        sensor_poses,
        features.tracks > 0 or any(d.mixture is not None for d in decisions),
        *anchor_times(alternatives, poses, node_times),
    )


def initial_poses(
    run: TeamRun,
    config: GraphConfig,
    timeline: Timeline,
    step_rel: list,
    decided_pose: dict,
    placed_via: dict,
) -> dict:
    """Each placed robot's initial poses (robot -> ([Pose3 per node], first seeded node)):
    known poses and decided ones carried along the robot's steps, then the robots placed
    through an observer (the max-mixture route)."""
    poses: dict = {}
    R = len(run.robots)
    order = [r for r in range(R) if r not in placed_via] + [r for r in placed_via]
    for r in order:
        placed = place_robot(
            run, r, timeline.node_times, step_rel, config, decided_pose, placed_via, poses
        )
        if placed is not None:
            poses[r] = placed
    return poses


def unplaced_robots(run: TeamRun, node_times: list, poses: dict) -> SkipReport:
    """A robot with poses that nothing placed: its poses are left out (counted)."""
    skips = SkipReport()
    for r, robot in enumerate(run.robots):
        if r not in poses and len(node_times[r]):
            skips.add(
                "unanchored_robot",
                f"robot {robot.name}: no initial pose, and nothing places it (no decided "
                f"candidate set, no placement by bearings, no accepted scan registration); "
                f"its {len(node_times[r])} poses are left out",
                len(node_times[r]),
            )
    return skips


def initial_values(
    poses: dict, landmark_guess: dict, marker_points: dict, frame_points: list
) -> dict:
    """key -> initial value: every placed robot's poses, the landmarks (a position, or 'from'
    a pose along a ray, where that pose is placed), the static markers and each moving
    target's per-set markers from the target's pose."""
    initial = {}
    for r in sorted(poses):
        for k, p in enumerate(poses[r][0]):
            initial[pose_key(r, k)] = p
    for lkey, guess in landmark_guess.items():
        landmark_initial(initial, lkey, guess)
    initial.update(marker_points)
    for key, ti, kt, local in frame_points:
        if pose_key(ti, kt) in initial:
            initial[key] = initial[pose_key(ti, kt)].transformFrom(local)
    return initial


def alternative_starts(
    run: TeamRun,
    config: GraphConfig,
    timeline: Timeline,
    step_rel: list,
    poses: dict,
    alternatives: dict,
    sensor_poses: dict,
) -> tuple[list, list]:
    """The other initial values the solve starts from (key -> value, over the initial values):
    one per alternative placement of a placed robot, carried along its steps; and those of
    robots placed by a guess (the online solve starts from these too)."""
    variants, guessed_variants = [], []
    for r, (starts, guessed) in alternatives.items():
        if r not in poses:
            continue
        for k0, body in starts:
            placed = place_robot(
                run, r, timeline.node_times, step_rel, config, {r: {k0: body}}, {}, poses
            )
            variants.append({pose_key(r, k): p for k, p in enumerate(placed[0])})
            with_sensors(variants[-1], sensor_poses)
            if guessed:
                guessed_variants.append(variants[-1])
    return variants, guessed_variants


def anchor_times(alternatives: dict, poses: dict, node_times: list) -> tuple[list, list]:
    """The node time each of `alternative_starts`' variants (and guessed variants), in their
    order, was placed at."""
    times, guessed_times = [], []
    for r, (starts, guessed) in alternatives.items():
        if r not in poses:
            continue
        for k0, _ in starts:
            times.append(float(node_times[r][k0]))
            if guessed:
                guessed_times.append(times[-1])
    return times, guessed_times


def time_steps(factors: list, initial: dict) -> tuple[list, list, int]:
    """Factors (time, factor, type) grouped by the time of their newest pose: the steps
    [(time, [(factor, type), ...]), ...], the kept factors' types in order, and the number of
    factors left out because they touch a variable with no initial value (an unplaced
    robot's)."""
    factors = sorted(factors, key=lambda f: f[0])
    kept, types = [], []
    dropped = 0
    for t, f, kind in factors:
        if all(key in initial for key in factor_keys(f)):
            kept.append((t, f, kind))
            types.append(kind)
        else:
            dropped += 1
    step_times = np.unique([k[0] for k in kept]) if kept else np.zeros(0)
    steps, j = [], 0
    for t in step_times:
        group = []
        while j < len(kept) and kept[j][0] == t:
            group.append(kept[j][1:])
            j += 1
        steps.append((float(t), group))
    return steps, types, dropped


def with_sensors(values: dict, sensor_poses: dict) -> dict:
    """`values` (key -> Pose3 / Point3) with the value of every sensor pose whose body pose it
    holds: the body pose composed with the extrinsics (in place; returned)."""
    for key, (body, E) in sensor_poses.items():
        if body in values:
            values[key] = values[body].compose(E)
    return values


def factor_keys(factor) -> list:
    """The variables of a graph item: a gtsam factor or a factor provider (`MaxMixture`)."""
    return list(factor.keys) if isinstance(factor, MaxMixture) else list(factor.keys())


def landmark_initial(initial: dict, lkey: int, guess) -> None:
    """A landmark's initial value into `initial`: a position, or ('from', r, k, direction,
    range) -- along a ray of pose (r, k), once that pose has an initial value."""
    if isinstance(guess, tuple) and guess and guess[0] == "from":
        _, r, k, direction, rng = guess
        if pose_key(r, k) in initial:
            initial[lkey] = initial[pose_key(r, k)].transformFrom(direction * rng)
    else:
        initial[lkey] = np.asarray(guess, dtype=float)
