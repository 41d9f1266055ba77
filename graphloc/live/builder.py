"""`LiveGraph`: the team graph of wheel-odometry robots built as rows arrive (the pose grid,
anchors and point measurements, each step emitted once no row can change it), and `build_live`,
the graph of a loaded run on either route (docs/design_team_graph.md, "The wheel route")."""

from __future__ import annotations

from dataclasses import replace
from itertools import islice

import numpy as np

from graphloc.keys import pose_key
from graphloc.live.coverage import NotLiveError, route, run_tables, wheel_problems
from graphloc.live.setup import empty_run
from graphloc.live.waiting import RobotState, WaitingPoints
from graphloc.pipelines.team_graph.config import GraphConfig, run_precision
from graphloc.pipelines.team_graph.graph import TeamGraph, count_graph, landmark_initial
from graphloc.pipelines.team_graph.motion import between_factor, robot_anchors
from graphloc.pipelines.team_graph.points import PointBuilder
from graphloc.run import TeamRun


class LiveGraph:
    """A `TeamGraph` (`graph`) grown from rows in time order: `velocity(r, row)` and
    `point(m)` take them, `advance(watermark)` returns the steps completed now that no row
    before `watermark` can arrive (each appended to graph.steps with the initial values of
    its variables in graph.initial), `finish()` the rest."""

    def __init__(self, run: TeamRun, config: GraphConfig, start_time: float | None):
        problems = wheel_problems(run, {r.name: ("odometry",) for r in run.robots})
        if problems:
            raise NotLiveError("not live yet: " + "; ".join(problems))
        self.run, self.config = run, config
        self.start = start_time
        self.robots = [RobotState(r, robot, run, config) for r, robot in enumerate(run.robots)]
        self.points = PointBuilder(run, config)
        self.waiting = WaitingPoints(config.keyframe_dt)  # those waiting for their poses
        self.arrived: list = []  # every point measurement, in arrival order (the run's points)
        self.horizon = max(config.keyframe_dt / 2, config.sync_tolerance) + 1e-6
        self.made = [0, 0, 0]  # point factors, landmark guesses, sensor poses taken so far
        self.first_seen = np.inf  # earliest row time (the start of a run without odometry)
        self.graph = TeamGraph(
            run,
            config,
            [r.times.view for r in self.robots],
            [[None] for _ in run.robots],
            precision=run_precision(run),
            sensor_poses=self.points.sensors.poses,
        )
        self.graph.skips.merge(run.skips)
        self.pending = StepQueue(self.graph)
        if self.start is not None:  # a static robot's one pose is at the start
            for robot in self.robots:
                if robot.robot.static:
                    self._grow(robot)

    # ---- rows in ------------------------------------------------------------------------------

    def velocity(self, r: int, rows) -> None:
        """Wheel-odometry rows (time, v, omega), one (3,) or many (N,3), of robot r."""
        rows = np.asarray(rows, dtype=float).reshape(-1, 3)
        if not len(rows):
            return
        self.first_seen = min(self.first_seen, rows[0, 0])
        robot = self.robots[r]
        robot.velocity.append(rows)
        if self.start is None:
            self._start_if_known()
        if self.start is not None:
            self._grow(robot)

    def point(self, m) -> None:
        """A point measurement (`graphloc.run.PointMeasurement`)."""
        self.first_seen = min(self.first_seen, m.time)
        self.arrived.append(m)
        if m.kind == "range_bearing":  # a breakpoint of the robot's dead reckoning, used or not
            self.robots[m.robot].frames.stamp(m.time)
        if self.points.used(m):  # else counted as left out by the options
            self.waiting.push(m)

    # ---- steps out ----------------------------------------------------------------------------

    def advance(self, watermark: float) -> list:
        """The steps completed when every row before `watermark` has arrived (time order)."""
        if self.start is None:
            return []
        self._take_points(watermark)
        end = min(robot.end for robot in self.robots)
        before = watermark - self.horizon  # no measurement that joins a pose there can come
        first = self.waiting.first_time()
        if first is not None:
            before = min(before, first - self.horizon)
        return self._emit(min(end, np.nextafter(before, -np.inf)))

    def finish(self) -> list:
        """Every row is in: the remaining steps."""
        for robot in self.robots:
            robot.finished = True
        if self.start is None:
            self._start_if_known(final=True)
            if self.start is None:
                return []
            for robot in self.robots:
                self._grow(robot)
        self._take_points(np.inf)
        steps = self._emit(np.inf)
        graph = self.graph
        for _, _, kind in self.pending.carried:  # no step came after them
            graph.skips.add(
                "after_last_step",
                f"a {kind} factor on poses of steps already solved (a static robot's row) "
                f"arrived after the last step: no step left to take it",
            )
        self.pending.carried = []
        graph.node_times = [robot.times.view.copy() for robot in self.robots]
        graph.anchored_from = {
            r: robot.times.view[0] for r, robot in enumerate(self.robots) if robot.times.n
        }
        for r, robot in enumerate(self.robots):
            if not robot.times.n and not robot.robot.static:
                graph.skips.add(
                    "unanchored_robot",
                    f"robot {robot.robot.name}: no odometry rows arrived, so it has no poses",
                )
        count_graph(self.graph, self.points, sum(robot.times.n for robot in self.robots))
        self.graph.skips.merge(self.points.made.skips)
        return steps

    def run_so_far(self) -> TeamRun:
        """The run of the rows that arrived."""
        start = float(self.start if self.start is not None else np.nan)
        velocity = tuple(robot.velocity.view.copy() for robot in self.robots)
        return replace(self.run, start_time=start, velocity=velocity, points=tuple(self.arrived))

    # ---- internals ----------------------------------------------------------------------------

    def _start_if_known(self, final: bool = False) -> None:
        """The run's start when the manifest gives none (`graphloc_log.team_run`): the latest
        first odometry time of the robots (once each has its first row), else the first row."""
        moving = [robot for robot in self.robots if not robot.robot.static]
        firsts = [robot.velocity.view[0, 0] for robot in moving if robot.velocity.n]
        if moving and (len(firsts) == len(moving) or (final and firsts)):
            self.start = float(max(firsts))
        elif final and np.isfinite(self.first_seen):
            self.start = float(self.first_seen)
        if self.start is not None:
            for robot in self.robots:
                self._grow(robot)

    def _grow(self, robot: RobotState) -> None:
        """New pose times of a robot (its grid up to its last odometry row: `WheelSteps`; a
        static robot's one pose), each step's factor and dead-reckoned initial value made."""
        config, r, k0 = self.config, robot.r, robot.times.n
        if robot.robot.static:
            steps, n = [], 1
        else:
            steps, n = robot.wheel.steps(self.start), robot.wheel.nodes
        if n <= k0:
            return
        robot.times.append(self.start + config.keyframe_dt * np.arange(k0, n))
        self.graph.node_times[r] = robot.times.view
        initial, step_rel = self.graph.initial, self.graph.step_rel[r]
        if k0 == 0:
            initial[pose_key(r, 0)] = robot.robot.initial_pose
        for k, (_, m) in enumerate(steps, start=max(k0, 1)):
            step_rel.append((m.relative, m.covariance))
            initial[pose_key(r, k)] = initial[pose_key(r, k - 1)].compose(m.relative)
            f = between_factor(r, k - 1, k, m.relative, m.covariance, config)
            self.pending.add(robot.times.view[k], (0, r, k), f, "odometry", carry=True)
        anchors = robot_anchors(r, robot.robot, config, robot.times.view, k0)  # prior, surfaces
        for j, (t, f, kind) in enumerate(anchors):
            self.pending.add(t, (1, r, j), f, kind, carry=True)

    def _take_points(self, watermark: float) -> None:
        """Point measurements whose poses are known (`WaitingPoints.take`), in arrival order,
        as factors."""
        node_times = self.graph.node_times
        taken = self.waiting.take(self.robots, self.start, watermark)
        for m, k, kt, corrected in taken:
            self.points.add(m, k, kt, node_times, corrected)
        if taken:
            self._take_made()

    def _take_made(self) -> None:
        """The point section's new factors and initial values (landmark guesses, sensor
        poses) into the graph."""
        points, initial, made = self.points, self.graph.initial, self.made
        for t, f, kind in points.made.factors[made[0] :]:
            made[0] += 1
            self.pending.add(t, (2, 0, made[0]), f, kind, carry=True)
        guesses = points.landmark_guess  # dicts that only grow: the new items are the last
        for lkey, guess in islice(guesses.items(), made[1], None):
            if lkey not in initial:
                landmark_initial(initial, lkey, guess)
        made[1] = len(guesses)
        for key, (body, E) in islice(points.sensors.poses.items(), made[2], None):
            if key not in initial:
                initial[key] = initial[body].compose(E)
        made[2] = len(points.sensors.poses)

    def _emit(self, bound: float) -> list:
        return [self.pending.emit(t) for t in self.pending.due(bound)]


class StepQueue:
    """Factors waiting for their step, the time of their newest pose (`add`), emitted into
    `graph.steps` in time order (`emit`), a step's factors in the order of their order keys; a
    factor on a step already emitted that may be `carry`-ed (a static robot's row, whose one
    pose is at the start) joins the next step."""

    def __init__(self, graph: TeamGraph):
        self.graph = graph
        self.steps: dict = {}  # step time -> [(order key, factor, type)]
        self.carried: list = []
        self.emitted = -np.inf  # time of the last emitted step

    def add(self, t: float, order: tuple, factor, kind: str, carry: bool = False) -> None:
        if carry and t <= self.emitted:
            self.carried.append((order, factor, kind))
        else:
            self.steps.setdefault(float(t), []).append((order, factor, kind))

    def due(self, bound: float) -> list:
        """The waiting step times up to `bound`, in time order."""
        return sorted(t for t in self.steps if t <= bound)

    def emit(self, t: float) -> tuple:
        """The step at time t (the carried factors first) into the graph."""
        if t <= self.emitted:
            raise NotLiveError(f"a factor at {t} after the step at {self.emitted}: not causal")
        group = sorted(self.steps.pop(t), key=lambda item: item[0])
        group, self.carried = self.carried + group, []
        step = (t, [(f, kind) for _, f, kind in group])
        self.graph.steps.append(step)
        self.graph.factor_types += [kind for _, _, kind in group]
        self.emitted = t
        return step


def build_live(run: TeamRun, config: GraphConfig) -> TeamGraph:
    """A loaded run's graph, built as the live team builds it (`coverage.route`): by `LiveGraph`
    (each robot's odometry at once, then the point measurements in the run's order) or
    `event_rows.build_events`; what `graphloc smooth` / `online` solve."""
    if route(run, run_tables(run)) == "event":  # event-clocked robots (`live.events`)
        from graphloc.live.event_rows import build_events

        return build_events(run, config)
    live = LiveGraph(empty_run(run), config, run.start_time)
    for r, rows in enumerate(run.velocity):
        live.velocity(r, rows)
    for m in run.points:
        live.point(m)
    live.finish()
    live.graph.run = run
    return live.graph
