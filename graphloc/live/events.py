"""`EventGraph`: the team graph of event-clocked robots (relative poses, scan steps, wheel grid
steps) built as rows arrive, with their candidate sets, scan registrations, point measurements
and camera tables; the causality and placement rules are in docs/design_team_graph.md."""

from __future__ import annotations

import bisect
from collections import deque
from dataclasses import replace
from functools import partial

import numpy as np

from graphloc.textio import SkipReport
from graphloc.live.builder import StepQueue
from graphloc.live.coverage import NotLiveError
from graphloc.live.event_camera import EventFeatures, camera_skips, release_circles
from graphloc.live.event_placement import (
    alternative_placements,
    initial_upto,
    seed_robot,
    start_variants,
)
from graphloc.live.event_points import EventPoints
from graphloc.live.event_scans import ScanLinks
from graphloc.live.event_sets import take_set
from graphloc.live.event_clock import (
    EventClock,
    EventRobot,
    final_end,
    inserted_times,
    measured,
    motion_bound,
    refused_motion,
)
from graphloc.pipelines.team_graph.config import FINE_PRECISION, GraphConfig, run_precision
from graphloc.pipelines.team_graph.graph import TeamGraph, count_graph
from graphloc.pipelines.team_graph.motion import (
    between_factor,
    robot_anchors,
    split_step,
)
from graphloc.run import TeamRun


class EventGraph:
    """A `TeamGraph` (`graph`) grown from relative poses (`motion(m)`) and candidate sets
    (`observation(o)`) in time order; `advance(watermark)` returns the completed steps,
    `finish()` the rest (module docstring)."""

    def __init__(
        self,
        run: TeamRun,
        config: GraphConfig,
        start_time: float | None,
        stamped,
        observers=frozenset(),
        camera=False,
        wheels=frozenset(),
    ):
        """stamped: robots whose pose times are at relative-pose stamps; observers: robots with
        candidate sets; camera: `TeamGraph.camera`; wheels: the stamped robots whose relative poses
        are wheel grid steps. iSAM2's precision: FINE_PRECISION with candidate sets, else
        `run_precision` of the relative poses before the first step."""
        self.run, self.config, self.wheels = run, config, frozenset(wheels)
        self.points = EventPoints(run, config, set(observers))
        self.start = start_time
        self.start_from_rows = False  # the start came from the first relative pose
        self.robots = [EventRobot(r, robot, r in stamped) for r, robot in enumerate(run.robots)]
        self.clock = EventClock(run, config, [np.zeros(0) for _ in run.robots])
        self.streams: dict = {}  # (observer, target, pixels) -> [StreamTracker, obs, index]
        self.mixtures: dict = {}  # (observer, unplaced target) -> [MixtureTracker, index]
        self.unplaced_sets: dict = {}  # (unplaced observer, unplaced target) -> sets skipped
        self.held_circles: dict = {}  # observer not placed yet -> its circle sets [(n, o)]
        self.features = EventFeatures(run, config)  # `live.event_camera`
        self.queue: deque = deque()  # candidate sets waiting for their poses, in arrival order
        self.arrived: list = []  # every candidate set, in arrival order
        self.marker_points: dict = {}
        self.first_seen = np.inf
        self.skips = SkipReport()
        self.graph = TeamGraph(
            run,
            config,
            self.clock.node_times,
            [r.steps for r in self.robots],
            precision=FINE_PRECISION if observers else np.nan,
        )
        self.graph.skips.merge(run.skips)
        self.graph.camera = camera
        self.pending = StepQueue(self.graph)
        self.links = ScanLinks(self)  # the inter-robot scan registration
        for r, robot in enumerate(run.robots):  # held by the online pass until placed
            if robot.initial_pose is None:
                self.graph.anchored_from[r] = np.inf

    # ---- rows in ------------------------------------------------------------------------------

    def motion(self, m) -> None:
        """A relative pose (`graphloc.run.Motion`) of an event-clocked robot."""
        robot = self.robots[m.robot]
        if not robot.stamped:
            raise NotLiveError(
                f"robot {robot.robot.name}: a relative pose, but its manifest has no "
                f"relative_pose table (its pose times are at its measurements)"
            )
        late = refused_motion(robot, m, self.start, self.start_from_rows)
        if late is not None:  # a live team cannot take it: counted, never the whole run
            self.skips.add("relative_pose_late", f"robot {robot.robot.name}: {late}")
            return
        self.first_seen = min(self.first_seen, m.t0)
        if self.start is None:  # the whole run's: the earliest relative-pose start
            self.start, self.start_from_rows = float(m.t0), True
        for t in (m.t0, m.t1):
            i = np.searchsorted(robot.stamps, t)
            if not (i < len(robot.stamps) and robot.stamps[i] == t):
                robot.stamps = np.insert(robot.stamps, i, t)
        robot.motions.append(m)
        robot.ends.append(m.t1)
        robot.span = max(robot.span, m.t1 - m.t0)

    def observation(self, o) -> None:
        """A candidate set (`graphloc.run.CandidateObservation`)."""
        self.first_seen = min(self.first_seen, o.time)
        self.arrived.append(o)
        late = [measured(self.robots[r], o.time, "a candidate set") for r in (o.robot, o.target)]
        if any(late):
            self.skips.add("set_late", next(filter(None, late)))
            return
        self.queue.append((len(self.arrived) - 1, o))

    def point(self, m) -> None:
        """A range, bearing or range-bearing (`graphloc.run.PointMeasurement`)."""
        self.first_seen = min(self.first_seen, m.time)
        robots = (m.robot, m.target) if m.target >= 0 else (m.robot,)
        late = [measured(self.robots[r], m.time, "a point measurement") for r in robots]
        if any(late):
            self.skips.add("point_late", next(filter(None, late)))
            return
        self.points.add(m)

    def feature(self, f) -> None:
        """A feature pixel (`graphloc.run.FeatureObservation`, `live.event_camera`)."""
        self.first_seen = min(self.first_seen, f.time)
        self.features.arrive(self, f)

    # ---- steps out ----------------------------------------------------------------------------

    def advance(self, watermark: float) -> list:
        """The steps completed when every row before `watermark` has arrived."""
        if self.start is None and not any(robot.stamped for robot in self.robots):
            if np.isfinite(self.first_seen):
                self.start = float(self.first_seen)
        if self.start is None:
            return []
        self._anchor_static()
        for robot in self.robots:
            self._times(robot, watermark)
        self._take_motions(watermark)
        points, robots, tol = self.points, self.robots, self.config.sync_tolerance
        carried = partial(self.pending.add, carry=True)  # a point row on a static robot's pose
        points.take(self.clock, lambda r: final_end(robots[r], watermark), carried)
        self._take_sets(watermark)
        self.features.take(self, watermark)
        self.links.pairs(lambda r: final_end(self.robots[r], watermark))
        finished = watermark == np.inf and all(robot.finished for robot in robots)
        points.place(robots, self.clock, partial(seed_robot, self.graph, self.config), finished)
        release_circles(self)
        for r, (starts, _) in points.resected.items():
            if not robots[r].variants:
                start_variants(self.graph, self.config, robots[r], starts)
        bound = min(motion_bound(robot, watermark) for robot in robots)
        held = np.inf if finished else points.hold_from(robots) - 1e-9
        bound = min(bound, self.links.bound(), watermark - tol - 1e-9, held)
        bound = min(bound, self.features.head() - tol - 1e-9)
        for head in ([self.queue[0][1]] if self.queue else []) + list(points.queue)[:1]:
            bound = min(bound, head.time - tol - 1e-9)
        return self._emit(bound)

    def finish(self) -> list:
        """Every row is in: the remaining steps, the graph's counts, decisions and alternatives; a
        robot nothing placed is a counted `unanchored_robot`, its factors held."""
        for robot in self.robots:
            robot.finished = True
        if self.start is None and np.isfinite(self.first_seen):
            self.start = float(self.first_seen)
        steps = self.advance(np.inf) if self.start is not None else self._emit(np.inf)
        self.links.finish(self.skips)
        camera_skips(self)
        unplaced_robots(self)
        record_graph(self)
        return steps

    # ---- internals ----------------------------------------------------------------------------

    def _anchor_static(self) -> None:
        for robot in self.robots:
            if robot.robot.static and not len(robot.times):
                robot.times = np.array([self.start])
                self.clock.node_times[robot.r] = robot.times
                robot.steps.append(None)
                if robot.robot.initial_pose is not None:
                    seed_robot(self.graph, self.config, robot, 0, robot.robot.initial_pose)
                self._anchors(robot)

    def _times(self, robot: EventRobot, watermark: float) -> None:
        """Robot's new final pose times: poses at its relative-pose stamps and at measurements
        inside a step (else at its measurements), over the rows that can shape times after its last
        final one, cut at what is final."""
        if robot.robot.static:
            return
        end = final_end(robot, watermark)
        n = len(robot.times)
        last = robot.times[-1] if n else -np.inf
        lo = last - robot.span - 2 * self.config.sync_tolerance - 1e-6
        measured = robot.measured[bisect.bisect_left(robot.measured, lo) :]
        if robot.stamped:
            motions = robot.motions[bisect.bisect_left(robot.ends, lo - robot.span) :]
            stamps = [t for m in motions for t in (m.t0, m.t1)]
            if stamps:
                stamps += inserted_times(robot, motions, measured, self.config.sync_tolerance)
        else:
            stamps = measured
        times = np.unique(np.round(np.array(stamps, dtype=float), 9))
        new = times[(times > last) & (times < end)]
        if len(new):
            robot.times = np.concatenate([robot.times, new])
            self.clock.node_times[robot.r] = robot.times
            robot.steps += [None] * len(new)
            if not n and robot.robot.initial_pose is not None:
                seed_robot(self.graph, self.config, robot, 0, robot.robot.initial_pose)
            self._anchors(robot)

    def _anchors(self, robot: EventRobot) -> None:
        made = robot_anchors(robot.r, robot.robot, self.config, robot.times, robot.anchors_done)
        for t, f, kind in made:
            robot.anchor_count += 1
            self.pending.add(t, (1, robot.r, robot.anchor_count), f, kind)
        robot.anchors_done = len(robot.times)

    def _take_motions(self, watermark: float) -> None:
        """Relative poses whose poses are final (their stamps are poses: `nearest` finds them
        exactly): their between factors (`motion_factors`), in arrival order."""
        for robot in self.robots:
            while robot.done < len(robot.motions):
                m = robot.motions[robot.done]
                if not max(m.t0, m.t1) < final_end(robot, watermark):
                    break
                self._motion_factors(robot, robot.done, m)
                robot.done += 1

    def _motion_factors(self, robot: EventRobot, index: int, m) -> None:
        r, times, config = robot.r, robot.times, self.config
        k0, k1 = self.clock.nearest(r, m.t0), self.clock.nearest(r, m.t1)
        if k0 < 0 or k1 < 0 or k0 == k1:
            self.skips.add(
                "no_pose_at_time",
                f"robot {robot.robot.name}: relative pose {m.t0}->{m.t1} has no poses",
            )
            return
        stamps = robot.stamps
        a, b = m.t0, m.t1
        consecutive = np.searchsorted(stamps, a, "right") >= np.searchsorted(stamps, b, "left")
        if consecutive and k1 > k0 + 1:
            parts = split_step(m.relative, m.covariance, times[k0 : k1 + 1])
        else:
            parts = [(m.relative, m.covariance)]
        nodes = range(k0, k1 + 1) if len(parts) > 1 else (k0, k1)
        for j, (x, y, (rel, cov)) in enumerate(zip(nodes[:-1], nodes[1:], parts)):
            f = between_factor(r, x, y, rel, cov, config)
            self.pending.add(times[max(x, y)], (0, r, index, j), f, "odometry")
            if y == x + 1 and robot.steps[y] is None:
                robot.steps[y] = (rel, cov)

    def _take_sets(self, watermark: float) -> None:
        """Candidate sets whose poses and the steps into them are final (the tracker takes
        the odometry between sets: `motion_bound`), in arrival order, through their streams."""
        tol = self.config.sync_tolerance
        while self.queue:
            n, o = self.queue[0]
            ends = [
                min(final_end(robot, watermark), motion_bound(robot, watermark))
                for robot in (self.robots[o.robot], self.robots[o.target])
            ]
            if o.time + tol >= min(ends):
                return
            self.queue.popleft()
            take_set(self, n, o)

    def _emit(self, bound: float) -> list:
        due = self.pending.due(bound)
        graph = self.graph
        if (due or bound == np.inf) and not np.isfinite(graph.precision):  # no candidate sets:
            motions = tuple(  # the steps so far
                m for robot in self.robots if robot.r not in self.wheels for m in robot.motions
            )
            graph.precision = run_precision(replace(self.run, motions=motions, observations=()))
        steps = []
        for t in due:
            initial_upto(graph, self.config, self.robots, t)
            self.points.initials(graph.initial, graph.guessed_alternatives)
            self.features.priors(self, t)
            self._frame_points()
            steps.append(self.pending.emit(t))
        if bound == np.inf:
            initial_upto(graph, self.config, self.robots, np.inf)
            self.points.initials(graph.initial, graph.guessed_alternatives)
            self._frame_points()
        return steps

    def _frame_points(self) -> None:
        """Initial values of a moving target's per-set marker points whose pose has one."""
        initial = self.graph.initial
        for key, (pose, local) in self.graph.frame_points.items():
            if key not in initial and pose in initial:
                initial[key] = initial[pose].transformFrom(local)


def record_graph(events) -> None:
    """Decisions, skips, alternatives and counts of `events` (an `EventGraph` whose rows are
    all in) into its graph."""
    graph = events.graph
    tracked = list(events.streams.values())
    ordered = sorted(
        [(i, t.out.outcomes, t.out.skips) for t, _, i in tracked]
        + [(i, t.outcomes, t.made.skips) for t, i in events.mixtures.values()],
        key=lambda item: item[0],
    )
    graph.decisions = [d for _, outcomes, _ in ordered for d in outcomes]
    for _, _, skips in ordered:
        graph.skips.merge(skips)
    robots = events.run.robots
    for (r, ti), n in events.unplaced_sets.items():
        graph.skips.add(
            "target_unplaced",
            f"robot {robots[r].name}: {n} candidate sets on robot {robots[ti].name}: neither "
            f"has an initial pose (no max-mixture places one through the other)",
            n,
        )
    graph.skips.merge(events.features.tracks.made.skips)
    graph.skips.merge(events.skips)
    points = events.points.builder
    graph.skips.merge(points.made.skips)
    streams = [tracker.out for tracker, _, _ in tracked]
    alternative_placements(graph, events.config, events.robots, streams, points.sensors.poses)
    count_graph(
        graph,
        points,
        sum(len(r.times) for r in events.robots if r.seed is not None),
        candidate_sets=len(events.arrived),
        marker_points=len(events.marker_points),
        committed_sets=sum(d.committed >= 0 for d in graph.decisions),
        feature_tracks=len(events.features.tracks.tracks),
    )


def unplaced_robots(events) -> None:
    """Robots nothing placed by the end of `events` (an `EventGraph` whose rows are all in):
    each a counted skip `unanchored_robot` naming why (its factors stay held)."""
    graph = events.graph
    for robot in events.robots:
        if robot.seed is not None:
            continue
        graph.anchored_from.pop(robot.r, None)
        if not len(robot.times):  # no rows: no poses
            continue
        why = (
            "nothing placed it (no decided candidate set, no marker-pixel set, no placement "
            "by mutual bearings, resection or scan registration)"
        )
        events.skips.add(
            "unanchored_robot",
            f"robot {robot.robot.name}: {why}; its {len(robot.times)} poses are left out",
            len(robot.times),
        )
