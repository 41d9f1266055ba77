"""A wheel-odometry robot's grid steps on both routes (`LiveGraph`'s pose grid, the event route's
relative poses): its odometry integrated over the grid start + k keyframe_dt
(`live.arc.ArcIntegrator`, bit for bit whatever the split), each step made once its odometry
reaches the step's end."""

from __future__ import annotations

import numpy as np

from graphloc.live.arc import ArcIntegrator, GrowingArray
from graphloc.pipelines.team_graph.config import GraphConfig
from graphloc.pipelines.team_graph.motion import velocity_noise
from graphloc.run import Motion, TeamRun, planar_covariance, pose_from_planar


class WheelSteps:
    """Robot r's odometry rows so far (`add`) and the grid steps they complete (`steps`)."""

    def __init__(self, r: int, run: TeamRun, config: GraphConfig):
        self.r, self.dt = r, config.keyframe_dt
        self.rows = GrowingArray(3)
        self.arc = ArcIntegrator(lambda: self.rows.view, velocity_noise(run, r, config))
        self.nodes = 0  # grid nodes made
        self.seen = 0  # rows whose grid nodes are made

    @property
    def first(self) -> float | None:
        """The time of the robot's first odometry row (None before it)."""
        return float(self.rows.view[0, 0]) if self.rows.n else None

    def add(self, rows) -> None:
        """Odometry rows (time, v, omega), one (3,) or many (N,3), in time order."""
        rows = np.asarray(rows, dtype=float).reshape(-1, 3)
        if len(rows):
            self.rows.append(rows)

    def steps(self, start: float) -> list[tuple[float, Motion]]:
        """The grid steps the rows so far complete and no call returned yet, each with the time
        of the row that completed it: (time, Motion) each, in time order."""
        times = self.rows.view[self.seen :, 0]
        if not len(times):
            return []
        self.seen = self.rows.n
        # nodes that exist once each row has arrived
        made = np.maximum(np.floor((times - start) / self.dt + 1e-9).astype(int) + 1, 1)
        n = int(made[-1])
        k0 = self.nodes
        if n <= k0:
            return []
        self.nodes = n
        grid = start + self.dt * np.arange(k0, n)
        _, deltas, covs = self.arc.advance(grid)
        first = max(k0, 1)  # node 0 has no step
        arrived = times[np.searchsorted(made, np.arange(first, n), side="right")]
        stamps = start + self.dt * np.arange(first - 1, n)
        return [
            (float(t), Motion(self.r, float(a), float(b), pose_from_planar(*d), c))
            for t, a, b, d, c in zip(
                arrived, stamps[:-1], stamps[1:], deltas, planar_covariance(covs)
            )
        ]


def wheel_motions(run: TeamRun, config: GraphConfig) -> list[tuple[float, Motion]]:
    """Every moving robot's grid steps of a loaded run (its whole odometry table at once),
    (time its last row arrived, Motion) each, in time order."""
    out: list = []
    for r, robot in enumerate(run.robots):
        if robot.static or not len(run.velocity[r]):
            continue
        wheel = WheelSteps(r, run, config)
        wheel.add(run.velocity[r])
        out += wheel.steps(run.start_time)
    return sorted(out, key=lambda e: (e[0], e[1].robot, e[1].t0))


def skip_relative(skips, robot, what: str = "relative pose") -> None:
    """Count a relative pose of a wheel-odometry robot as skipped (`skips`: a SkipReport)."""
    skips.add(
        "relative_pose_of_wheel_robot",
        f"robot {robot.name}: a {what} of a robot with wheel odometry (its poses are on its "
        f"odometry grid): not used",
    )
