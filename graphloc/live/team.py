"""`LiveTeam`: a running team's rows pushed as they arrive, one iSAM2 update per completed time
step, each robot's latest pose (with its marginal covariance when asked) after every update.

    team = graphloc.LiveTeam.open("runs/team1", options=graphloc.RunOptions(), window=0.5)
    team.subscribe(lambda update: print(update.time, update.poses))
    team.push("robot1", "odometry", {"time": 12.0, "sensor": "wheels", "v": 0.2, "omega": 0.0})
    team.latest("robot1")  # RobotPose: time, gtsam.Pose3, 6x6 covariance (or None)
    result = team.finish()  # the TeamResult `solve(graph, mode="online")` gives

Rows (docs/log_format.md columns, text or numbers) are checked (`rows.RowChecker`), held for
`window` seconds and released in time order (`rows.TimeWindow`), built into the team graph
(`builder.LiveGraph`) and solved step by step by the online pass of `graphloc online`
(`team_graph.passes.Pass`)."""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, replace
from pathlib import Path

import gtsam
import numpy as np

from graphloc.exitcodes import SolverFailure
from graphloc.io import SkipReport
from graphloc.keys import pose_key
from graphloc.live.builder import LiveGraph
from graphloc.live.rows import RowChecker, TimeWindow
from graphloc.live.setup import LiveSetup, live_setup
from graphloc.pipelines.team_graph.passes import Pass, TeamResult
from graphloc.run import PointMeasurement


@dataclass(frozen=True)
class RobotPose:
    """A robot's latest estimated pose: its time [s], node index, world_T_body and the 6x6
    marginal covariance in GTSAM's Pose3 tangent order (rx, ry, rz, tx, ty, tz), None when not
    asked for."""

    time: float
    index: int
    pose: gtsam.Pose3
    covariance: np.ndarray | None


@dataclass(frozen=True)
class LiveUpdate:
    """One iSAM2 update: the graph step's index and time, the latest pose of every robot that
    got a new pose in it (name -> RobotPose), the factors it added and its latency [s] (wall
    time from the step's completion to its estimates, covariances included)."""

    step: int
    time: float
    poses: dict
    factors: int
    latency_s: float


class LiveTeam:
    """A team solved as its rows arrive (module docstring). `open` it from a run's setup."""

    def __init__(self, setup: LiveSetup, window: float = 0.5):
        self.setup = setup
        self.skips = SkipReport()
        self.skips.merge(setup.run.skips)
        self.checker = RowChecker(
            setup.manifest, setup.run.robots, setup.noise, setup.landmark_ids, self.skips
        )
        self.window = TimeWindow(window, self.skips)
        self.builder = LiveGraph(setup.run, setup.config, setup.start_time)
        self.graph = self.builder.graph
        self.graph.skips = self.skips
        self.names = [r.name for r in setup.run.robots]
        self.solver = Pass(self.graph, "online", None, False, None)
        self.solver_note = ""
        self.subscribers: list = []
        self.rows = 0
        self.finished: TeamResult | None = None

    @classmethod
    def open(cls, source, options=None, window: float = 0.5) -> "LiveTeam":
        """A live team of the run at `source`: a log directory's manifest.json (its tables may
        be empty or absent) or an MRCLAM directory's robots and landmarks; `options`: the
        `RunOptions` of `graphloc online`; `window` [s]: how late a row may arrive and still be
        put in time order. `builder.NotLiveError` names what of the run is not live yet."""
        return cls(live_setup(Path(source), options), window)

    # ---- in --------------------------------------------------------------------------------

    def subscribe(self, callback, covariance: bool = True) -> None:
        """callback(LiveUpdate) after every iSAM2 update (with each pose's marginal covariance
        when `covariance`)."""
        self.subscribers.append((callback, covariance))

    def push(self, robot: str, table: str, row) -> None:
        """One row of robot `robot`'s `table` (column -> text or number): checked, put in time
        order, and every step it completes solved."""
        self._check_open()
        self.rows += 1
        item = self.checker.check(robot, table, row, self.rows)
        if item is not None:
            self._arrive(_item_time(item), (table, item), f"robot {robot!r}, table {table!r}")

    def push_many(self, robot: str, table: str, rows) -> None:
        """Rows of one robot's table, in the order they arrived (`push` each)."""
        for row in rows:
            self.push(robot, table, row)

    def push_item(self, item) -> None:
        """An item as a table's handler makes it -- (robot index, (time, v, omega)) of an
        odometry row, a `PointMeasurement` --, already checked (a loaded run's rows)."""
        self._check_open()
        table = "points" if isinstance(item, PointMeasurement) else "odometry"
        self._arrive(_item_time(item), (table, item), "item")

    # ---- out -------------------------------------------------------------------------------

    def latest(self, robot: str, covariance: bool = True) -> RobotPose | None:
        """Robot `robot`'s latest pose as now estimated, None before its first."""
        r = self.names.index(robot)
        if r not in self.solver.latest:
            return None
        return self._pose(r, covariance)

    def finish(self) -> TeamResult:
        """Every held row in, every remaining step solved: the `TeamResult` of the run."""
        if self.finished is not None:
            return self.finished
        self._release(self.window.flush(), np.inf)
        self._solve(self.builder.finish())
        self.graph.run = replace(
            self.setup.run,
            start_time=float(self.builder.start if self.builder.start is not None else np.nan),
            velocity=tuple(robot.velocity.view.copy() for robot in self.builder.robots),
            points=tuple(self.builder.arrived),
        )
        result = self.solver.result()
        self.finished = replace(
            result,
            wall_s=self.solver.wall,
            survivors=[],
            hypotheses=1,
            solver_note=self.solver_note or result.solver_note,
        )
        return self.finished

    # ---- internals -------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self.finished is not None:
            raise ValueError("LiveTeam.push after finish(): the run is over")

    def _arrive(self, t: float, entry, where: str) -> None:
        released = self.window.add(t, entry, where)
        if released:
            self._release(released, self.window.front)

    def _release(self, entries: list, front: float) -> None:
        builder = self.builder
        for table, item in entries:
            if table == "odometry":
                builder.velocity(item[0], item[1])
            elif table != "groundtruth":  # evaluation only
                builder.point(item)
        self._solve(builder.advance(front))

    def _solve(self, steps: list) -> None:
        for _ in steps:
            t0 = _time.perf_counter()
            i = self.solver.done
            before = dict(self.solver.latest)
            try:
                self.solver.step(i)
            except SolverFailure as exc:
                self._refactor(exc, i)
            changed = [
                r for r, (k, _) in self.solver.latest.items() if before.get(r, (-1,))[0] != k
            ]
            wanted = any(cov for _, cov in self.subscribers)
            poses = {self.names[r]: self._pose(r, wanted) for r in changed}
            update = LiveUpdate(
                i,
                self.graph.steps[i][0],
                poses,
                len(self.graph.steps[i][1]),
                _time.perf_counter() - t0,
            )
            for callback, covariance in self.subscribers:
                callback(
                    update
                    if covariance or not wanted
                    else replace(
                        update,
                        poses={n: replace(p, covariance=None) for n, p in poses.items()},
                    )
                )

    def _refactor(self, exc: Exception, i: int) -> None:
        """Cholesky found the system indeterminate: the pass again with QR from the first step
        (`team_graph.solve` does the same for a whole run)."""
        if self.graph.config.factorization == "QR":
            raise exc
        self.graph.config = replace(self.graph.config, factorization="QR")
        self.solver = Pass(self.graph, "online", None, False, None)
        for j in range(i + 1):
            self.solver.step(j)
        self.solver_note = f"QR factorization (Cholesky failed: {exc})"

    def _pose(self, r: int, covariance: bool) -> RobotPose:
        k, _ = self.solver.latest[r]
        key = pose_key(r, k)
        session = self.solver.session
        pose = session.estimate([key]).atPose3(key)
        cov = session.marginal_covariance(key) if covariance else None
        return RobotPose(float(self.graph.node_times[r][k]), k, pose, cov)


def _item_time(item) -> float:
    """The time of a handler's item (`datasets.log_rows.TABLE_HANDLERS`)."""
    if isinstance(item, PointMeasurement):
        return float(item.time)
    return float(item[1][0])  # (robot, (time, ...)): odometry, planar ground truth
