"""The camera sections of `live.events.EventGraph` (seed 003: KLT feature tracks, a teammate's
base seen as two circle candidates): feature pixels as projection factors (`EventFeatures`),
circle sets of an unplaced target as max-mixtures (`mixture_set`), a camera not placed yet
holding both (docs/design_team_graph.md, "Camera tables")."""

from __future__ import annotations

from collections import deque
from dataclasses import replace

import gtsam
import numpy as np

from graphloc.keys import pose_key
from graphloc.live.coverage import NotLiveError
from graphloc.live.event_clock import final_end
from graphloc.live.event_placement import initial_upto, seed_robot
from graphloc.pipelines.team_graph.camera import FeatureTracks
from graphloc.pipelines.team_graph.graph import landmark_initial
from graphloc.pipelines.team_graph.mixtures import MixtureTracker


class EventFeatures:
    """Feature pixels (`graphloc.run.FeatureObservation`) of an `EventGraph`, in time order:
    held until their poses are final (`take`), then factors; the tracks' point priors enter
    with their first pixel's step (`priors`)."""

    def __init__(self, run, config):
        self.config = config
        self.tracks = FeatureTracks(run, config)
        self.queue: deque = deque()
        self.arrived: list = []  # every pixel, in arrival order
        self.taken = 0  # pixels made into factors (their order key)
        self.priors_done = 0  # point priors looked at
        self.waiting: list = []  # ... of those, the ones whose camera was not placed then
        self.pixels_of: dict = {}  # robot -> its pixels made into factors

    def arrive(self, events, f) -> None:
        """One pixel: its time is one of its robot's measurement times (a pose inside a
        relative-pose step, `event_clock.inserted_times`)."""
        robot = events.robots[f.robot]
        built = robot.times
        if len(built) and f.time < built[-1]:
            raise NotLiveError(
                f"robot {robot.robot.name}: a feature pixel at {f.time}, after its pose times "
                f"up to {built[-1]} were built (rows out of time order)"
            )
        if robot.measured and f.time < robot.measured[-1]:
            raise NotLiveError(
                f"robot {robot.robot.name}: feature pixels out of time order ({f.time} after "
                f"{robot.measured[-1]})"
            )
        if not robot.measured or robot.measured[-1] != f.time:
            robot.measured.append(f.time)
        self.arrived.append(f)
        self.queue.append(f)

    def head(self) -> float:
        """The time of the oldest pixel still waiting (inf: none)."""
        return self.queue[0].time if self.queue else np.inf

    def take(self, events, watermark: float) -> None:
        """The waiting pixels whose robot's poses near them are final, as projection factors."""
        tol = self.config.sync_tolerance
        while self.queue:
            f = self.queue[0]
            if f.time + tol >= final_end(events.robots[f.robot], watermark):
                return
            self.queue.popleft()
            k = events.clock.nearest(f.robot, f.time)
            time = events.clock.node_times[f.robot][k] if k >= 0 else np.nan
            for t, factor, kind in self.tracks.add(f, k, time):
                events.pending.add(t, (3, self.taken), factor, kind)
                self.pixels_of[f.robot] = self.pixels_of.get(f.robot, 0) + 1
            self.taken += 1

    def priors(self, events, t: float) -> None:
        """The point priors of tracks whose first pixel's step is at or before t, at the landmark's
        guess once that pose has its initial value; a prior whose camera was not placed then waits
        for the step that places it (`_placed_step`)."""
        tracks, graph = self.tracks, events.graph
        new = []
        while self.priors_done < len(tracks.point_priors):
            if tracks.point_priors[self.priors_done][2] > t:
                break
            new.append(self.priors_done)
            self.priors_done += 1
        waiting, self.waiting = self.waiting, []
        for i in waiting + new:
            lkey, sigma, time = tracks.point_priors[i]
            landmark_initial(graph.initial, lkey, tracks.landmark_guess[lkey])
            if lkey not in graph.initial:
                self.waiting.append(i)
                continue
            noise = gtsam.noiseModel.Isotropic.Sigma(3, sigma)
            prior = gtsam.PriorFactorPoint3(lkey, graph.initial[lkey], noise)
            at = _placed_step(graph, tracks.landmark_guess[lkey][1], time)
            events.pending.add(at, (9, i), prior, "feature_prior")


def mixture_set(events, n: int, o) -> None:
    """Candidate set n (`o`) of an observer on a target without an initial pose through its stream's
    `MixtureTracker`; an observer not placed yet holds it (`events.held_circles`) until it is."""
    if events.robots[o.robot].seed is None:
        events.held_circles.setdefault(o.robot, []).append((n, o))
        return
    release_circles(events, o.robot)
    _mixture_set(events, o)


def release_circles(events, r: int | None = None) -> None:
    """The held circle sets of observer r (None: of every observer) that is placed now, in
    the order they arrived, through their streams; their factors join the step that placed
    it (`_placed_step`)."""
    for observer in [r] if r is not None else list(events.held_circles):
        if events.robots[observer].seed is None:
            continue
        for _, o in events.held_circles.pop(observer, []):
            _mixture_set(events, o)


def _mixture_set(events, o) -> None:
    run, config, graph = events.run, events.config, events.graph
    r, ti = o.robot, o.target
    observer = events.robots[r]
    entry = events.mixtures.get((r, ti))
    if entry is None:
        tracked = run
        if run.robots[r].initial_pose is None:  # dead-reckoned from its placed first pose
            robots = list(run.robots)
            robots[r] = replace(robots[r], initial_pose=graph.initial[pose_key(r, 0)])
            tracked = replace(run, robots=tuple(robots))
        entry = [MixtureTracker(tracked, config, r, ti), len(events.streams) + len(events.mixtures)]
        events.mixtures[(r, ti)] = entry
    tracker, index = entry
    before = tracker.placed
    k, kt = events.clock.nearest(r, o.time), events.clock.nearest(ti, o.time)
    tracker.add(o, k, kt, observer.steps)
    at = -np.inf
    for t, factor, kind in tracker.factor_times(events.clock.node_times):
        at = _placed_step(graph, r, t)
        events.pending.add(at, (4, index, len(tracker.outcomes), 0), factor, kind)
        d = tracker.outcomes[-1]
        if d.mixture is not None and d.relative is not None:
            graph.links[pose_key(r, k)] = (pose_key(ti, kt), d.relative)
    if before is None and tracker.placed is not None:
        ((k_target, (_, k_observer, rel)),) = tracker.placed.items()
        initial_upto(graph, config, [observer], float(observer.times[k_observer]))
        pose = graph.initial[pose_key(r, k_observer)].compose(rel)
        seed_robot(graph, config, events.robots[ti], k_target, pose)
        # held until the step of the set that placed it (a camera placed late: that step)
        graph.anchored_from[ti] = max(graph.anchored_from[ti], at)


def camera_skips(events) -> None:
    """Every row is in: the feature pixels and held circle sets of a camera nothing placed,
    counted skips `unplaced_camera` naming robot and table (module docstring)."""
    names = events.run.robots
    for r, robot in enumerate(events.robots):
        if robot.seed is not None:
            continue
        pixels = events.features.pixels_of.get(r, 0)
        if pixels:
            tracks = sum(1 for (owner, _) in events.features.tracks.tracks if owner == r)
            events.skips.add(
                "unplaced_camera",
                f"robot {names[r].name}: table 'features': {pixels} pixels of {tracks} tracks "
                f"from a camera nothing placed (a landmark's guess is on its first pixel's ray)",
                pixels,
            )
        held = events.held_circles.get(r, [])
        for ti in sorted({o.target for _, o in held}):
            sets = sum(1 for _, o in held if o.target == ti)
            events.skips.add(
                "unplaced_camera",
                f"robot {names[r].name}: table 'ellipses': {sets} circle sets of "
                f"{names[ti].name} from a camera nothing placed (they place {names[ti].name} "
                f"through its pose)",
                sets,
            )


def _placed_step(graph, r: int, t: float) -> float:
    """The step a factor made at step time t that waited for robot r's placement joins: t, or
    the step r was placed at, if later (not emitted yet: the rows that place a robot are
    factors of that step), so the graph does not depend on when the placement came."""
    return max(t, graph.anchored_from.get(r, -np.inf))
