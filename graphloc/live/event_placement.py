"""Where event-clocked robots start (`live.events.EventGraph`): a robot placed at a known or
decided pose (`seed_robot`: `motion.place_robot`'s seeds, its earlier poses carried back along
its steps; the pose a marker-pixel stream's placing set gives, `stream_placement`), the initial
values of placed robots' later poses carried forward (`initial_upto`), and the pixel streams'
alternative placements a batch solve starts from too (the candidates of their first set, as
`candidates.place_observers` makes them: `alternative_placements`)."""

from __future__ import annotations

import numpy as np

from graphloc.keys import pose_key
from graphloc.live.coverage import NotLiveError
from graphloc.live.event_clock import EventRobot
from graphloc.pipelines.team_graph.config import GraphConfig
from graphloc.pipelines.team_graph.graph import TeamGraph, alternative_starts, anchor_times
from graphloc.pipelines.team_graph.motion import step_or_unknown
from graphloc.run import TeamRun


def seed_robot(graph: TeamGraph, config: GraphConfig, robot: EventRobot, k: int, pose) -> None:
    """A known or decided pose of robot at node k (`motion.place_robot`'s seeds): the first
    places the robot, its earlier poses carried back along its steps."""
    if k in robot.placed:
        return
    robot.placed[k] = pose
    if robot.seed is not None:
        if k < robot.seed:
            raise NotLiveError(f"robot {robot.robot.name}: a decision before its placement")
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


def alternative_placements(
    run: TeamRun, config: GraphConfig, clock, graph: TeamGraph, robots: list, streams: list
) -> None:
    """The pixel streams' alternative placements (`candidates.place_observers`, used by a
    batch solve), carried along the steps as `graph.alternative_starts` carries them."""
    alternatives = {}
    for s in streams:
        if s.pixel_route and s.sets:
            first = s.sets[0]
            alternatives[s.robot] = ([(first.k, body) for body in first.bodies], False)
    poses = {
        robot.r: (
            [graph.initial[pose_key(robot.r, k)] for k in range(len(robot.times))],
            robot.seed,
        )
        for robot in robots
        if robot.seed is not None
    }
    variants, _ = alternative_starts(run, config, clock, graph.step_rel, poses, alternatives, {})
    graph.alternatives = variants
    graph.alternative_times = anchor_times(alternatives, poses, clock.node_times)[0]
