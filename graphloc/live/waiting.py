"""The wheel route's robots and measurements (`live.builder.LiveGraph`): each robot's live state
(`RobotState`: odometry rows, grid steps, pose times, and the dead reckoning its range-bearing
rows are re-expressed with, `RangeBearingFrames`), and the point measurements held until their
poses are known (`WaitingPoints`: released in arrival order as the longest ready run from the
queue's front, found in NumPy; a row pushed live is a batch of one)."""

from __future__ import annotations

import numpy as np

import heapq
from collections import OrderedDict

from graphloc.live.arc import ArcIntegrator, GrowingArray
from graphloc.live.wheel_steps import WheelSteps
from graphloc.pipelines.team_graph.config import GraphConfig
from graphloc.pipelines.team_graph.motion import velocity_noise
from graphloc.pipelines.team_graph.points import body_frame_points
from graphloc.run import TeamRun


class RangeBearingFrames:
    """A wheel-odometry robot's range-bearing rows re-expressed in its body frame at the node
    each joins (`points.body_frame_points`): dead reckoning over the node times and every
    range-bearing time, carried forward (`ArcIntegrator`, so bit for bit whatever the split)."""

    def __init__(self, samples, noise):
        self.arc = ArcIntegrator(samples, noise, covariances=False)
        self.stamps: list = []  # heap of range-bearing times not integrated yet
        self.at = OrderedDict()  # stamp -> planar pose, in increasing stamps

    def stamp(self, t: float) -> None:
        """A range-bearing row of the robot at time t arrived."""
        heapq.heappush(self.stamps, t)

    def body_frame(self, points: list, node_times: np.ndarray, joined: np.ndarray) -> list:
        """`points` (range-bearing rows in time order, every range-bearing time up to the
        latest of them and of their nodes arrived), each in the body frame at its node time
        `joined` (of `node_times`): (direction (3,), range) each."""
        t = np.array([m.time for m in points])
        upto = float(max(t.max(), joined.max()))
        last = -np.inf if self.arc.stamp is None else self.arc.stamp
        lo, hi = np.searchsorted(node_times, [last, upto], "right")
        due = []  # the range-bearing times up to `upto` (those at or before `last` are done)
        while self.stamps and self.stamps[0] <= upto:
            s = heapq.heappop(self.stamps)
            if s > last:
                due.append(s)
        known = np.union1d(node_times[lo:hi], due)
        if len(known):
            poses, _, _ = self.arc.advance(known)
            self.at.update(zip(known.tolist(), poses))
        at = self.at
        at_meas = np.array([at[s] for s in t.tolist()])
        at_node = np.array([at[s] for s in joined.tolist()])
        out = body_frame_points(points, at_meas, at_node)
        # later rows are at or after the last one's time and join nodes at or after its node
        # (the stamps enter `at` in increasing order: each call's after the last integrated)
        oldest = min(t[-1], joined[-1])
        while at and next(iter(at)) < oldest:
            at.popitem(last=False)
        return out


class RobotState:
    """One robot's live state: its odometry rows, pose times, step integration and the frames
    of its range-bearing rows."""

    def __init__(self, r: int, robot, run: TeamRun, config: GraphConfig):
        self.r, self.robot = r, robot
        self.wheel = WheelSteps(r, run, config)
        self.velocity = self.wheel.rows
        self.times = GrowingArray()
        self.finished = False
        noise = velocity_noise(run, r, config)
        self.frames = RangeBearingFrames(lambda: self.velocity.view, noise)

    @property
    def end(self) -> float:
        """Time up to which the robot's pose times are final."""
        if self.finished or self.robot.static:
            return np.inf
        return self.velocity.view[-1, 0] if self.velocity.n else -np.inf


class WaitingPoints:
    """Point measurements (`graphloc.run.PointMeasurement`) in arrival order (`push`), taken
    from the front once their poses are known (`take`)."""

    def __init__(self, keyframe_dt: float):
        self.dt = keyframe_dt
        self.items: list = []
        self.fields = GrowingArray(4)  # time, robot, target, range-bearing (1) or not (0)
        self.head = 0  # items[head:] wait
        # the first waiting one's wait: (the state of its robots then, the watermark it needs)
        self.blocked: tuple | None = None

    def push(self, m) -> None:
        self.items.append(m)
        self.fields.append([m.time, m.robot, m.target, m.kind == "range_bearing"])

    def first_time(self) -> float | None:
        """Time of the first measurement waiting, None if none waits."""
        return self.items[self.head].time if self.head < len(self.items) else None

    def take(self, robots: list, start: float, watermark: float) -> list:
        """The measurements whose poses are known now that every row before `watermark` has
        arrived, from the front of the queue up to the first that must wait: (measurement,
        robot node k, target node kt (-1: none within the tolerance), its (direction, range)
        in the body frame at node k or None: as measured) each, in arrival order."""
        out, size = [], 1
        if self.blocked is not None:  # nothing it waits for happened: it waits still
            state, needs = self.blocked
            if watermark < needs and state == self._state(robots):
                return out
        self.blocked = None
        while self.head < len(self.items):
            length = min(size, len(self.items) - self.head)
            t, r, target, rb = self.fields.view[self.head : self.head + length].T
            r, target = r.astype(int), target.astype(int)
            ready, known, k, kt, joined = self._ready(
                robots, start, watermark, t, r, target, rb > 0
            )
            n = int(np.argmin(ready)) if not ready.all() else len(ready)
            out += self._taken(robots, n, r, k, kt, joined)
            self.head += n
            if n < length:
                self.blocked = (self._state(robots), joined[n] if known[n] else np.inf)
                break
            size *= 2
        if self.head > 4096 and self.head * 2 > len(self.items):  # drop what was taken
            self.items = self.items[self.head :]
            rest = self.fields.view[self.head :].copy()
            self.fields = GrowingArray(4)
            self.fields.append(rest)
            self.head = 0
        return out

    def _state(self, robots) -> tuple:
        """What the first waiting measurement's readiness depends on but the watermark: its
        robot's and target's pose times (start + k dt: their number), whether their odometry
        is past it, whether they are finished."""
        m = self.items[self.head]
        robot = robots[m.robot]
        state = (robot.times.n, robot.finished, robot.end > m.time)
        if m.target >= 0:
            robot = robots[m.target]
            state += (robot.times.n, robot.finished, robot.end > m.time)
        return state

    def _ready(self, robots, start, watermark, t, r, target, rb) -> tuple:
        """Per measurement: ready, poses known (ready but for the range-bearing's node time
        not yet passed by the watermark), robot node, target node, and the node time a
        range-bearing is re-expressed at (NaN: taken as measured)."""
        ready = np.ones(len(t), dtype=bool)
        k = np.full(len(t), -1)
        kt = np.full(len(t), -1)
        joined = np.full(len(t), np.nan)
        for i in set(r.tolist()):  # (np.unique, np.clip: slow on the few rows pushed live)
            sel = r == i
            known, k[sel] = nearest(robots[i], start, self.dt, t[sel])
            ready[sel] = known
            robot = robots[i]
            correct = sel & rb & (k >= 0)
            if not robot.velocity.n or not correct.any():
                continue
            times = robot.times.view
            f = np.rint((t[correct] - times[0]) / self.dt)
            waits = f > len(times) - 1 if not robot.finished else np.zeros(len(f), bool)
            t_f = times[np.minimum(np.maximum(f, 0), len(times) - 1).astype(int)]
            ready[correct] &= ~waits  # its node (a tie: the later) to come
            joined[correct] = t_f
        for i in set(target[target >= 0].tolist()):
            sel = target == i
            known, kt[sel] = nearest(robots[i], start, self.dt, t[sel])
            ready[sel] &= known
        passed = np.isnan(joined) | (joined <= watermark)
        return ready & passed, ready, k, kt, joined

    def _taken(self, robots, n: int, r, k, kt, joined) -> list:
        """The first n waiting as `take` gives them, range-bearing rows re-expressed."""
        if not n:
            return []
        items = self.items[self.head : self.head + n]
        corrected: list = [None] * n
        r, correct = r[:n], ~np.isnan(joined[:n])
        for i in set(r[correct].tolist()):
            mine = np.flatnonzero(correct & (r == i))
            robot = robots[i]
            local = robot.frames.body_frame(
                [items[j] for j in mine.tolist()], robot.times.view, joined[mine]
            )
            for j, value in zip(mine.tolist(), local):
                corrected[j] = value
        return list(zip(items, k[:n].tolist(), kt[:n].tolist(), corrected))


def nearest(robot: RobotState, start: float, dt: float, t: np.ndarray) -> tuple:
    """(known, index of the robot's pose nearest each of times t, -1 if none within dt/2) over its
    final pose times; known False while a later grid pose could still be the answer (within the
    tolerance of t and nearer than the nearest so far; a tie goes to the earlier pose)."""
    if robot.robot.static:
        return np.full(len(t), robot.times.n > 0), np.zeros(len(t), dtype=int)
    times = robot.times.view
    n = len(times)
    if not n:
        return np.full(len(t), robot.finished), np.full(len(t), -1)
    known = np.ones(len(t), dtype=bool) if robot.finished else robot.end > t
    i = np.minimum(np.maximum(times.searchsorted(t), 1), n - 1) if n > 1 else np.zeros(len(t), int)
    i = i - ((i > 0) & (np.abs(times[i - 1] - t) <= np.abs(times[i] - t)))
    gap = np.abs(times[i] - t)
    tol = dt / 2 + 1e-9
    if not robot.finished:
        following = start + dt * n  # as `LiveGraph._grow` places it
        known &= ~((t > following) | ((following - t <= tol) & (following - t < gap)))
    return known, np.where(gap <= tol, i, -1)
