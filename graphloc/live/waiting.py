"""`WaitingPoints`: the point measurements `live.builder.LiveGraph` holds until their poses are
known, released in arrival order as the longest ready run from the queue's front (found in
NumPy; a row pushed live is a batch of one)."""

from __future__ import annotations

import numpy as np

from graphloc.live.arc import GrowingArray
from graphloc.live.robot_state import RobotState


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
    """(known, index of the robot's pose nearest each of times t or -1) as
    `motion.Timeline.nearest` gives it over the robot's final pose times; known False until the
    robot's odometry is past t while a later grid pose (the next, start + n dt, once the
    odometry reaches it) could be the answer: within the tolerance of t and nearer than the
    nearest pose so far (a tie goes to the earlier pose)."""
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
