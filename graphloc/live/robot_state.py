"""One wheel-odometry robot's live state in `live.builder.LiveGraph`: its odometry rows and grid
steps (`wheel_steps.WheelSteps`), pose times, and the dead reckoning its range-bearing rows are
re-expressed with (`RangeBearingFrames`), each carried forward as rows arrive."""

from __future__ import annotations

import heapq
from collections import OrderedDict

import numpy as np

from graphloc.live.arc import ArcIntegrator, GrowingArray
from graphloc.live.wheel_steps import WheelSteps
from graphloc.pipelines.team_graph.config import GraphConfig
from graphloc.pipelines.team_graph.motion import velocity_noise
from graphloc.pipelines.team_graph.points import body_frame_points
from graphloc.run import TeamRun


class RangeBearingFrames:
    """A wheel-odometry robot's range-bearing rows re-expressed in its body frame at the node
    each joins (`points.body_frame_points`): dead reckoning over the node times and every
    range-bearing time, as the whole run's `points._corrected_range_bearings` integrates it,
    carried forward (`ArcIntegrator`, so bit for bit whatever the split)."""

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
