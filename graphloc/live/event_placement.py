"""Where event-clocked robots start (`live.events.EventGraph`): a robot placed at a known or
decided pose (`seed_robot`), initial values carried along its steps (`initial_upto`), and the
alternative placements a solve starts from too (`start_variants`, `alternative_placements`)."""

from __future__ import annotations

import numpy as np

from graphloc.keys import pose_key
from graphloc.live.event_clock import EventRobot
from graphloc.pipelines.team_graph.config import GraphConfig
from graphloc.pipelines.team_graph.graph import TeamGraph, with_sensors
from graphloc.pipelines.team_graph.motion import step_or_unknown


def seed_robot(graph: TeamGraph, config: GraphConfig, robot: EventRobot, k: int, pose) -> None:
    """A known or decided pose of robot at node k: the first places the robot, its earlier poses
    carried back along its steps; a later one is the initial value at k, one before the placement is
    no seed."""
    if k in robot.placed or (robot.seed is not None and k < robot.seed):
        return
    robot.placed[k] = pose
    if robot.seed is not None:
        return
    robot.seed = k
    initial, r = graph.initial, robot.r
    initial[pose_key(r, k)] = pose
    for j in range(k - 1, -1, -1):
        step = step_or_unknown(robot.steps, j + 1, config)[0]
        initial[pose_key(r, j)] = initial[pose_key(r, j + 1)].compose(step.inverse())
    robot.initial_done = k + 1
    graph.anchored_from[r] = float(robot.times[k])


def stream_placement(tracked) -> object:
    """Where the set (`candidates.TrackedSet`) that places a marker-pixel stream's observer
    puts it (`events.EventGraph`: its first decided set, or its `guess_after_sets`-th set):
    the decided candidate, else the tracker's best guess there -- the candidate of highest
    posterior after every set so far (`HypothesisTracker.update`)."""
    if tracked.decided:
        return tracked.bodies[tracked.update.committed]
    return tracked.bodies[int(np.argmax(tracked.update.probabilities))]


def initial_upto(graph: TeamGraph, config: GraphConfig, robots: list, t: float) -> None:
    """Initial values of placed robots' poses up to time t (carried along their steps)."""
    initial = graph.initial
    for robot in robots:
        if robot.seed is None:
            continue
        r = robot.r
        while robot.initial_done < len(robot.times) and robot.times[robot.initial_done] <= t:
            k = robot.initial_done
            if k in robot.placed:
                initial[pose_key(r, k)] = robot.placed[k]
            else:
                step = step_or_unknown(robot.steps, k, config)[0]
                initial[pose_key(r, k)] = initial[pose_key(r, k - 1)].compose(step)
            robot.initial_done += 1
        extend_variants(robot, config, robot.initial_done)


def start_variants(graph: TeamGraph, config: GraphConfig, robot: EventRobot, starts: list) -> None:
    """A robot placed by a guess (resection, or a pixel stream undecided after `guess_after_sets`
    sets): every start (node, world_T_body) an alternative the online solve runs as a hypothesis,
    carried along the robot's steps as its poses grow, judged from its own node's time."""
    r = robot.r
    robot.variant_starts += starts
    for k0, body in starts:
        v = {pose_key(r, k0): body}
        for j in range(k0 - 1, -1, -1):
            step = step_or_unknown(robot.steps, j + 1, config)[0]
            v[pose_key(r, j)] = v[pose_key(r, j + 1)].compose(step.inverse())
        robot.variants.append((k0 + 1, v))
    extend_variants(robot, config, robot.initial_done)
    graph.guessed_alternatives += [v for _, v in robot.variants]
    graph.guessed_alternative_times += _variant_times(robot, starts)


def _variant_times(robot: EventRobot, starts: list) -> list:
    """The node time each start (node, world_T_body) of a guessed robot was placed at."""
    return [float(robot.times[k0]) for k0, _ in starts]


def extend_variants(robot: EventRobot, config: GraphConfig, n: int) -> None:
    """A guessed robot's alternatives carried forward along its steps to its first n poses."""
    r = robot.r
    for j, (done, v) in enumerate(robot.variants):
        for k in range(done, n):
            step = step_or_unknown(robot.steps, k, config)[0]
            v[pose_key(r, k)] = v[pose_key(r, k - 1)].compose(step)
        robot.variants[j] = (max(done, n), v)


def alternative_placements(
    graph: TeamGraph, config: GraphConfig, robots: list, streams: list, sensor_poses: dict
) -> None:
    """The alternative placements a solve starts from too: the pixel streams' (every candidate
    of the stream's first set, carried along the observer's steps; batch only) and the guessed
    robots' (`start_variants`: the online solve runs them as hypotheses too), with the node time
    each was placed at (`alternative_times`, `guessed_alternative_times`)."""
    firsts = {}  # robot -> the first set of its last pixel stream
    for s in streams:
        if s.pixel_route and s.sets and not robots[s.robot].variants:
            firsts[s.robot] = s.sets[0]
    variants, times = [], []
    for r, first in firsts.items():
        robot = robots[r]
        if robot.seed is None:
            continue
        for body in first.bodies:
            poses = _carried(robot, config, first.k, body)
            variants.append(
                with_sensors({pose_key(r, k): p for k, p in enumerate(poses)}, sensor_poses)
            )
            times.append(float(robot.times[first.k]))
    guessed = [with_sensors(v, sensor_poses) for robot in robots for _, v in robot.variants]
    guessed_times = [t for robot in robots for t in _variant_times(robot, robot.variant_starts)]
    graph.alternatives, graph.guessed_alternatives = variants + guessed, guessed
    graph.alternative_times = times + guessed_times
    graph.guessed_alternative_times = guessed_times


def _carried(robot: EventRobot, config: GraphConfig, k0: int, body) -> list:
    """Robot's poses with node k0 at `body` (node 0 at its initial pose, where it has one),
    carried along its steps."""
    out: list = [None] * len(robot.times)
    if robot.robot.initial_pose is not None:
        out[0] = robot.robot.initial_pose
    if out[k0] is None:
        out[k0] = body
    seed = 0 if out[0] is not None else k0
    for k in range(seed + 1, len(out)):
        if out[k] is None:
            out[k] = out[k - 1].compose(step_or_unknown(robot.steps, k, config)[0])
    for k in range(seed - 1, -1, -1):
        out[k] = out[k + 1].compose(step_or_unknown(robot.steps, k + 1, config)[0].inverse())
    return out
