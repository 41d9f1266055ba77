"""The event clock of `live.events.EventGraph`: one robot's rows so far (`EventRobot`), the pose
a measurement joins (`EventClock`), and which pose times are final (`final_end`,
`motion_bound`; poses inside a step at measurements, `inserted_times`)."""

from __future__ import annotations

import numpy as np

from graphloc.pipelines.team_graph.config import GraphConfig
from graphloc.run import TeamRun


class EventClock:
    """The robots' final pose times (`node_times`) and the pose a measurement at time t joins
    (`nearest`: within `sync_tolerance`, else -1)."""

    def __init__(self, run: TeamRun, config: GraphConfig, node_times: list):
        self.run, self.config, self.node_times = run, config, node_times

    def nearest(self, r: int, t: float) -> int:
        if self.run.robots[r].static:
            return 0
        times = self.node_times[r]
        n = len(times)
        if not n:
            return -1
        i = min(max(int(times.searchsorted(t)), 1), n - 1) if n > 1 else 0
        if i > 0 and abs(times[i - 1] - t) <= abs(times[i] - t):
            i -= 1
        return i if abs(times[i] - t) <= self.config.sync_tolerance else -1


class EventRobot:
    """One robot's rows so far: relative poses (in arrival order), measured times, its final
    pose times and steps, and its placement."""

    def __init__(self, r: int, robot, stamped: bool):
        self.r, self.robot = r, robot
        self.stamped = stamped  # pose times at relative-pose stamps (else at measurements)
        self.motions: list = []
        self.ends: list = []  # each relative pose's end time, in arrival (time) order
        self.stamps = np.zeros(0)  # every relative-pose stamp, sorted
        self.span = 0.0  # the longest relative pose [s]
        self.done = 0  # motions made into factors
        self.measured: list = []
        self.times = np.zeros(0)  # final pose times
        self.steps: list = []  # step_rel
        self.placed: dict = {}  # node -> decided / initial pose (the seeds)
        self.seed: int | None = None  # first seeded node
        self.initial_done = 0  # nodes whose initial value is set
        self.variants: list = []  # a guessed placement's alternatives: (nodes done, key -> Pose3)
        self.variant_starts: list = []  # ... and where each starts: (node, world_T_body)
        self.anchors_done = 0
        self.anchor_count = 0
        self.finished = False


def final_end(robot: EventRobot, watermark: float) -> float:
    """Pose times before this (or at it, for a relative-pose stamp bound) are final."""
    if robot.finished:
        return np.inf
    if robot.stamped:
        last = max((m.t1 for m in robot.motions), default=-np.inf)
        return min(watermark, np.nextafter(last, np.inf))
    return watermark


def motion_bound(robot: EventRobot, watermark: float) -> float:
    """Steps up to this time may be emitted as far as this robot is concerned: before the
    final pose times, and before the first factor of a relative pose not made yet (its end,
    or the first pose inside it: a measurement's, where the step is split)."""
    if robot.robot.static:
        return np.inf
    end = final_end(robot, watermark)
    if robot.done < len(robot.motions):
        times = robot.times
        for m in robot.motions[robot.done :]:
            inside = times[np.searchsorted(times, m.t0 + 1e-6, "right") :][:1]
            end = min(end, min([m.t1, *inside]) - 1e-9)
    return end - 1e-9 if np.isfinite(end) else end


def inserted_times(robot: EventRobot, motions: list, measured: list, tol: float) -> list:
    """The times of `measured` inside one of `motions`' consecutive steps (no stamp of the robot's
    relative poses strictly inside it) and farther than `tol` from every stamp: poses there, the
    step split at them."""
    stamps = robot.stamps
    spans = []
    for m in motions:
        a, b = m.t0, m.t1
        i, j = np.searchsorted(stamps, a, "right"), np.searchsorted(stamps, b, "left")
        if i >= j:
            spans.append((a, b))
    if not spans or not measured:
        return []
    cons = np.unique([t for s in spans for t in s])
    spans = np.array(sorted(spans))
    t = np.unique(np.asarray(measured, dtype=float))
    i = np.clip(np.searchsorted(cons, t), 1, len(cons) - 1)
    gap = np.minimum(np.abs(cons[i - 1] - t), np.abs(cons[i] - t))
    k = np.searchsorted(spans[:, 0], t, "right") - 1
    inside = (k >= 0) & (t < spans[np.clip(k, 0, None), 1])
    return t[(gap > tol) & inside].tolist()


def measured(robot: EventRobot, t: float, what: str) -> str | None:
    """A measurement at t of robot: a pose time to come. Out of time order (before pose times
    already built, or before its previous measurement): the reason it is refused, else None."""
    built = robot.times
    if not robot.robot.static and len(built) and t < built[-1]:
        return (
            f"robot {robot.robot.name}: {what} at {t}, after its pose times up to "
            f"{built[-1]} were built (rows out of time order)"
        )
    if robot.measured and t < robot.measured[-1]:
        return (
            f"robot {robot.robot.name}: measurements out of time order ({what} at {t} "
            f"after {robot.measured[-1]})"
        )
    robot.measured.append(t)
    return None


def refused_motion(robot: EventRobot, m, start, start_from_rows: bool) -> str | None:
    """Why a relative pose cannot join the robot's steps as it arrives, or None: it starts
    before the run's start that the first relative pose set, runs backwards, ends before the
    robot's last one (out of time order), or starts or ends inside steps already built without
    being a pose time of them (it would change final pose times or steps)."""
    if start_from_rows and m.t0 < start:
        return f"a relative pose from {m.t0}, before the start {start} the first one set"
    if m.t0 > m.t1:
        return f"a relative pose from {m.t0} to the earlier {m.t1}"
    if robot.ends and m.t1 < robot.ends[-1]:
        return f"relative poses out of time order ({m.t1} after {robot.ends[-1]})"
    built = robot.times
    for t in (m.t0, m.t1):
        if len(built) and t < built[-1]:
            i = np.searchsorted(robot.stamps, t)
            if not (i < len(robot.stamps) and robot.stamps[i] == t):
                return (
                    f"a relative pose from {t}, inside steps already built (up to "
                    f"{built[-1]}): it would change their pose times"
                )
    return None
