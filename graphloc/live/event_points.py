"""Point measurements of `live.events.EventGraph` as their poses become final, and the robots
their bearings place (seed 000, 000_05137a0a9c449be3.txt; docs/design_team_graph.md,
"Bearings"): three static robots by mutual bearings (Sec. III-A, `place_by_mutual_bearings`)
and a robot resected by P3P on its bearings of three placed static robots (Sec. IV,
`resection_candidates`). Initial values only: the bearings are factors."""

from __future__ import annotations

from collections import deque
from dataclasses import replace
from itertools import combinations

import gtsam
import numpy as np

from graphloc.geometry.p3p import solve_p3p
from graphloc.pipelines.team_graph.graph import landmark_initial
from graphloc.pipelines.team_graph.config import GraphConfig
from graphloc.pipelines.team_graph.points import PointBuilder
from graphloc.run import TeamRun
from graphloc.vision.mutual import localize_three_bearings

RESECTION_SETS = 3  # a resected robot's solve starts from the P3P candidates of its first sets


def _bearings(run: TeamRun) -> tuple[dict, dict]:
    """(observer, target) -> unit direction in the observer's BODY frame (the first row of
    each pair), and {a, b} -> range [m] for robot-to-robot ranges (either direction)."""
    bearing, ranges = {}, {}
    for m in run.points:
        if m.target < 0:
            continue
        if m.kind in ("bearing", "range_bearing"):
            d = m.body_T_sensor.rotation().rotate(np.asarray(m.direction, float))
            bearing.setdefault((m.robot, m.target), np.asarray(d))
        if m.kind in ("range", "range_bearing"):
            ranges.setdefault(frozenset((m.robot, m.target)), m.range)
    return bearing, ranges


def place_by_mutual_bearings(run: TeamRun, placed: dict) -> dict:
    """Static robots without an initial pose placed by mutual bearings with a placed static
    robot (module docstring). placed: robot -> world_T_body of robots already placed (static
    ones with a known pose). Returns robot -> world_T_body for the robots placed here."""
    bearing, ranges = _bearings(run)
    static = [r for r, robot in enumerate(run.robots) if robot.static]
    out: dict = {}
    for trio in combinations(static, 3):
        known = [r for r in trio if r in placed or r in out]
        if len(known) != 1 or not all((i, j) in bearing for i in trio for j in trio if i != j):
            continue
        pair = next((p for p in combinations(trio, 2) if frozenset(p) in ranges), None)
        if pair is None:
            continue
        order = [*pair, next(r for r in trio if r not in pair)]
        u = np.full((1, 3, 3, 3), np.nan)
        for a, i in enumerate(order):
            for b, j in enumerate(order):
                if i != j:
                    u[0, a, b] = bearing[(i, j)]
        res = localize_three_bearings(u, ranges[frozenset(pair)])
        if not res.ok[0]:
            continue
        # res: pose of order[j] in order[0]'s frame; into the world through the placed robot
        k = known[0]
        world_T_k = placed[k] if k in placed else out[k]
        local = [res.pose3(0, 1, j + 1) for j in range(3)]
        world_T_0 = world_T_k.compose(local[order.index(k)].inverse())
        for j, rr in enumerate(order):
            if rr != k:
                out[rr] = world_T_0.compose(local[j])
    return out


def resection_candidates(run: TeamRun, r: int, positions: dict, sets: int) -> list:
    """Robot r's candidate world_T_body poses from P3P on its bearings, at each of the first
    `sets` times it sees three placed static robots (robot -> (3,) world position):
    [(time, world_T_body), ...], empty if it never does. One snapshot's P3P may miss the
    genuine pose (noise pushes it past the reprojection check near a degenerate configuration),
    so the later snapshots' candidates are starts too."""
    rows: dict = {}
    for m in run.points:
        if m.robot == r and m.kind == "bearing" and m.target in positions:
            d = m.body_T_sensor.rotation().rotate(np.asarray(m.direction, float))
            rows.setdefault(m.time, {}).setdefault(m.target, np.asarray(d))
    times = [t for t in sorted(rows) if len(rows[t]) >= 3][:sets]
    out = []
    for t in times:
        targets = sorted(rows[t])[:3]
        f = np.array([rows[t][j] for j in targets])
        X = np.array([positions[j] for j in targets])
        cand = solve_p3p(f[None], X[None])
        out += [
            (t, gtsam.Pose3(gtsam.Rot3(cand.R_wc[0, c]), cand.t_wc[0, c]))
            for c in np.flatnonzero(cand.valid[0])
        ]
    return out


class EventPoints:
    """The point rows of an event-clocked team so far (`add` as they arrive, `take` once their
    poses are final) and the placements their bearings make (module docstring). `resected`:
    robot -> its alternative starts ([(node, world_T_body), ...], True: a guess)."""

    def __init__(self, run: TeamRun, config: GraphConfig, observers: set):
        self.run, self.config = run, config
        self.builder = PointBuilder(run, config)
        self.queue: deque = deque()  # rows waiting for their poses, in arrival order
        self.arrived: list = []  # every row, in arrival order
        self.taken: list = []  # rows made into factors (or skipped), in arrival order
        self.made = 0  # the builder's factors handed to the graph
        self.observers = observers  # robots a candidate stream places (not resected)
        self.resected: dict = {}
        self.first_set: dict = {}  # robot -> time of its first complete resection set
        self.seen: dict = {}  # robot -> time -> robots its bearings at that time see
        self.placed_at = 0  # rows taken when `place` last looked

    def add(self, m) -> None:
        self.arrived.append(m)
        self.queue.append(m)

    def take(self, clock, final_end, emit) -> None:
        """Rows whose poses are final (`final_end(r)`: robot r's pose times before it are),
        in arrival order, as factors: emit(time, order, factor, type)."""
        tol = self.config.sync_tolerance
        builder = self.builder
        while self.queue:
            m = self.queue[0]
            ends = [final_end(m.robot)] + ([final_end(m.target)] if m.target >= 0 else [])
            if m.time + tol >= min(ends):
                return
            self.queue.popleft()
            self.taken.append(m)
            if m.kind == "bearing" and m.target >= 0:
                self.seen.setdefault(m.robot, {}).setdefault(m.time, set()).add(m.target)
            if builder.used(m):
                k = clock.nearest(m.robot, m.time)
                kt = -1 if m.target < 0 else clock.nearest(m.target, m.time)
                builder.add(m, k, kt, clock.node_times)
            robots = self.run.robots
            static = robots[m.robot].static and (m.target < 0 or robots[m.target].static)
            for t, f, kind in builder.made.factors[self.made :]:
                self.made += 1  # a static robot's row: in the step of its own time
                emit(max(t, m.time) if static else t, (2, self.made), f, kind)

    def place(self, robots: list, clock, seed, finished: bool) -> None:
        """Place the robots the rows taken so far place (module docstring): seed(robot, node,
        world_T_body) for each new placement."""
        unplaced = [r for r in robots if r.seed is None and r.robot.initial_pose is None]
        if not unplaced or not self.taken or (self.placed_at == len(self.taken) and not finished):
            return
        self.placed_at = len(self.taken)
        run = replace(self.run, points=tuple(self.taken))
        known = {
            r.r: r.robot.initial_pose
            for r in robots
            if r.robot.static and r.robot.initial_pose is not None
        }
        if any(r.robot.static for r in unplaced):
            for i, pose in place_by_mutual_bearings(run, known).items():
                if robots[i].seed is None and len(robots[i].times):
                    seed(robots[i], 0, pose)
        placed = {
            r.r: r.placed[0] for r in robots if r.robot.static and r.seed is not None and r.placed
        }
        positions = {i: np.asarray(p.translation()) for i, p in {**known, **placed}.items()}
        complete = self.queue[0].time if self.queue else np.inf
        for robot in unplaced:
            r = robot.r
            if robot.seed is not None or r in self.observers:
                continue
            if robot.robot.static and not finished:  # mutual bearings place it first
                continue
            seen = self.seen.get(r, {})
            sets = [
                t for t in sorted(seen) if t < complete and len(seen[t] & positions.keys()) >= 3
            ]
            if sets:
                self.first_set.setdefault(r, sets[0])
            if not sets or (len(sets) < RESECTION_SETS and not finished):
                continue
            starts = [
                (clock.nearest(r, t), body)
                for t, body in resection_candidates(run, r, positions, RESECTION_SETS)
            ]
            starts = [(k, body) for k, body in starts if k >= 0]
            if starts:
                self.resected[r] = (starts, True)
                seed(robot, *starts[0])

    def hold_from(self, robots: list) -> float:
        """No step at or after this time may be emitted yet: a static robot waiting for its
        placement by mutual bearings holds every step (its pose is at the start), a robot
        waiting for its resection the steps from its first set on."""
        out = np.inf
        for robot in robots:
            if robot.seed is not None or robot.robot.initial_pose is not None:
                continue
            if robot.robot.static and robot.r not in self.observers:
                out = -np.inf
            elif robot.r in self.first_set:
                out = min(out, clock_time(robot, self.config, self.first_set[robot.r]))
        return out

    def initials(self, initial: dict, alternatives: list = ()) -> None:
        """The landmark guesses and offset sensors' poses whose pose has an initial value, and
        the sensors' poses of the guessed alternatives (`TeamGraph.guessed_alternatives`, as
        the finished graph's `with_sensors` gives them: a pass the live team steps now reads
        its own sensor poses, not the guess's)."""
        builder = self.builder
        for lkey, guess in builder.landmark_guess.items():
            if lkey not in initial:
                landmark_initial(initial, lkey, guess)
        for values in (initial, *alternatives):
            for key, (body, E) in builder.sensors.poses.items():
                if key not in values and body in values:
                    values[key] = values[body].compose(E)


def clock_time(robot, config: GraphConfig, t: float) -> float:
    """The earliest pose time a row at t can join (within the sync tolerance)."""
    times = robot.times
    near = times[np.abs(times - t) <= config.sync_tolerance] if len(times) else times
    return float(near.min()) if len(near) else t - config.sync_tolerance
