"""`LiveTeam`: a running team's rows pushed as they arrive, one iSAM2 update per completed time
step, each robot's latest pose (with its marginal covariance when asked) after every update
(docs/api.md, "Live").

    team = graphloc.LiveTeam.open("runs/team1", options=graphloc.RunOptions(), window=0.5)
    team.push("robot1", "odometry", {"time": 12.0, "sensor": "wheels", "v": 0.2, "omega": 0.0})
    result = team.finish()  # the TeamResult `solve(graph, mode="online")` gives
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, replace
from pathlib import Path

import gtsam
import numpy as np

from graphloc.checkpoint import read_checkpoint, read_checkpoint_file, write_checkpoint
from graphloc.exitcodes import SolverFailure
from graphloc.textio import SkipReport
from graphloc.keys import pose_key
from graphloc.live.builder import LiveGraph
from graphloc.live.coverage import route, tables_of
from graphloc.live.rows import RowChecker, TimeWindow
from graphloc.live.setup import LiveSetup, live_setup
from graphloc.pipelines.team_graph.passes import TeamResult
from graphloc.pipelines.team_graph.side_by_side import SideBySide, start_times
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
    time from the step's completion to its estimates, covariances included) and the CPU time
    [s] of the same span (the process's: a latency a busy machine does not inflate)."""

    step: int
    time: float
    poses: dict
    factors: int
    latency_s: float
    cpu_s: float = 0.0


class LiveTeam:
    """A team solved as its rows arrive (module docstring). `open` it from a run's setup."""

    def __init__(
        self,
        setup: LiveSetup,
        window: float = 0.5,
        checkpoint: Path | None = None,
        checkpoint_every: int = 500,
    ):
        if not (type(checkpoint_every) is int and checkpoint_every >= 1):
            raise ValueError(f"checkpoint_every must be an integer >= 1, got {checkpoint_every!r}")
        self.setup = setup
        self.skips = SkipReport()
        self.skips.merge(setup.run.skips)
        self.window = TimeWindow(window, self.skips)
        self.builder, tables = live_builder(setup, self.skips)
        self.checker = RowChecker(
            setup.manifest, setup.run.robots, setup.noise, setup.landmark_ids, self.skips, tables
        )
        self.graph = self.builder.graph
        self.graph.skips = self.skips
        self.names = [r.name for r in setup.run.robots]
        # the online passes, made at the first step (the builder sets the graph's precision by
        # then): one, and one more per alternative start of a robot placed by a guess
        self.solver: SideBySide | None = None
        self.solver_note = ""
        self.subscribers: list = []
        self.callback_errors: list = []  # exceptions of subscribers, raised after the step
        self.rows = 0
        self.closed = False  # finish() began: no more rows
        self.finished: TeamResult | None = None
        # checkpoints (`checkpoint`): every row pushed, in push order, and when they were written
        self.checkpoint_path = None if checkpoint is None else Path(checkpoint)
        self.checkpoint_every = checkpoint_every
        self.pushed: list | None = None if checkpoint is None else []
        self.resumed = 0  # rows replayed from the checkpoint the team was opened with
        if self.checkpoint_path is not None and self.checkpoint_path.exists():
            self._resume(self.checkpoint_path)

    @classmethod
    def open(
        cls,
        source,
        options=None,
        window: float = 0.5,
        checkpoint=None,
        checkpoint_every: int = 500,
    ) -> "LiveTeam":
        """A live team of the run at `source`: a log directory's manifest.json (its tables may
        be empty or absent) or an MRCLAM directory's robots and landmarks; `options`: the
        `RunOptions` of `graphloc online`; `window` [s]: how late a row may arrive and still be
        put in time order. `coverage.NotLiveError` names what of the run is not live yet.
        checkpoint: a file (`graphloc.checkpoint`'s format, with the rows pushed so far)
        written every `checkpoint_every` steps and by `finish` / `write_checkpoint`; when it
        exists at open, the team resumes from it (its rows replayed: the same state, checked by
        the graph's fingerprint), so nothing pushed before it is lost."""
        return cls(live_setup(Path(source), options), window, checkpoint, checkpoint_every)

    # ---- in --------------------------------------------------------------------------------

    def subscribe(self, callback, covariance: bool = True) -> None:
        """callback(LiveUpdate) after every iSAM2 update (with each pose's marginal covariance
        when `covariance`)."""
        self.subscribers.append((callback, covariance))

    def push(self, robot: str, table: str, row) -> None:
        """One row of robot `robot`'s `table` (column -> text or number): checked (a refused
        row counted in `skips`, named by robot, table, its number among the rows pushed to the
        team and the field), put in time order, and every step it completes solved."""
        if self.closed:
            raise ValueError(
                f"robot {robot!r}, table {table!r}: LiveTeam.push after finish(): the run is "
                f"over (the row is not taken)"
            )
        self.checker.refuse(robot, table, row)  # raises: the push is no row (not counted)
        self.rows += 1
        if self.pushed is not None:
            self.pushed.append([robot, table, {str(k): _plain(v) for k, v in row.items()}])
        item = self.checker.check(robot, table, row, self.rows)
        if item is not None:
            where = f"robot {robot!r}, table {table!r}, row {self.rows}"
            rank = self.checker.rank(robot, table)
            released = self.window.add(_item_time(item), (table, item), where, rank)
            if released:
                self._release(released, self.window.front)
        self._raise_callback_error()

    # ---- out -------------------------------------------------------------------------------

    def latest(self, robot: str, covariance: bool = True) -> RobotPose | None:
        """Robot `robot`'s latest pose as now estimated, None before its first."""
        if robot not in self.names:
            raise ValueError(f"unknown robot {robot!r}; robots: {sorted(self.names)}")
        r = self.names.index(robot)
        if self.solver is None or r not in self.solver.best.latest:
            return None
        return self._pose(r, covariance)

    def finish(self) -> TeamResult:
        """Every held row in, every remaining step solved: the `TeamResult` of the run."""
        if self.finished is not None:
            return self.finished
        self._close()
        self.graph.run = self.builder.run_so_far()
        solver = self._solver()
        result = solver.result()
        if self.checkpoint_path is not None:
            self.write_checkpoint(finished=True)
        self.finished = replace(
            result,
            wall_s=sum(p.wall for p in solver.passes),
            solver_note=self.solver_note or result.solver_note,
        )
        self._raise_callback_error()  # the team is finished: finish() again returns the result
        return self.finished

    def write_checkpoint(self, finished: bool = False) -> None:
        """Write the checkpoint file now (`open`'s `checkpoint`): the graph's position and
        fingerprint, and every row pushed so far (those still held in the window too);
        `finished`: written by `finish` (a team resumed from it is finished too)."""
        if self.checkpoint_path is None:
            raise ValueError("LiveTeam.write_checkpoint: the team was opened without a checkpoint")
        write_checkpoint(
            self.checkpoint_path,
            self.graph,
            self._done(),
            {
                "live": {
                    "window": self.window.window,
                    "rows": self.pushed,
                    "finished": finished,
                }
            },
        )

    # ---- internals -------------------------------------------------------------------------

    def _resume(self, path: Path) -> None:
        """Replay the rows of the checkpoint at `path` and check the graph is the one it was
        written from (ValueError naming the file otherwise)."""
        data = read_checkpoint_file(path, allow_nan=True)
        live = data.get("live")
        rows = live.get("rows") if isinstance(live, dict) else None
        if not isinstance(rows, list) or not all(
            isinstance(r, list) and len(r) == 3 and isinstance(r[2], dict) for r in rows
        ):
            raise ValueError(
                f"{path}: field 'live.rows' must list [robot, table, row] (a checkpoint of "
                f"graphloc online, not of a live team?)"
            )
        if live.get("window") != self.window.window:
            raise ValueError(
                f"{path}: written with window {live.get('window')} s, opened with "
                f"{self.window.window} s; open with the same window"
            )
        every, self.checkpoint_every = self.checkpoint_every, 0  # no writes while replaying
        try:
            for robot, table, row in rows:
                self.push(robot, table, row)
            if live.get("finished") is True:
                self._close()
        finally:
            self.checkpoint_every = every
        read_checkpoint(path, self.graph, allow_nan=True)  # the same run, options and steps
        if data["steps_done"] != self._done():
            raise ValueError(
                f"{path}: field 'steps_done' is {data['steps_done']}, its rows give "
                f"{self._done()} steps"
            )
        self.resumed = len(rows)

    def _close(self) -> None:
        """No more rows: the held ones released, the remaining steps solved (once)."""
        if self.closed:
            return
        self.closed = True
        self._release(self.window.flush(), np.inf)
        self._solve(self.builder.finish())

    def _raise_callback_error(self) -> None:
        """The first exception a subscriber raised during this call, raised again now that
        every step of it is solved and every other subscriber called."""
        if self.callback_errors:
            first, self.callback_errors = self.callback_errors[0], []
            raise first

    def _release(self, entries: list, front: float) -> None:
        builder = self.builder
        for table, item in entries:
            if table == "odometry":
                builder.velocity(item[0], item[1])
            elif table != "groundtruth":  # evaluation only
                builder.point(item)
        self._solve(builder.advance(front))

    def _solve(self, steps: list) -> None:
        """Solve every step the builder emitted that the passes have not (`steps`: the new ones); a
        robot placed by a guess adds a pass per alternative start as the builder makes them
        (`SideBySide.add`)."""
        while self.graph.steps and self._solver().done < len(self.graph.steps):
            t0, cpu0 = _time.perf_counter(), _time.process_time()
            solver = self.solver
            guessed = self.graph.guessed_alternatives
            if len(solver.passes) < 1 + len(guessed):
                n = len(solver.passes) - 1
                times = start_times(guessed, self.graph.guessed_alternative_times)
                solver.add(guessed[n:], None if times is None else times[1 + n :])
            i = solver.done
            before = dict(solver.best.latest)
            try:
                solver.step(i)
            except SolverFailure as exc:
                self._refactor(exc, i)
            latest = self.solver.best.latest
            changed = [r for r, (k, _) in latest.items() if before.get(r, (-1,))[0] != k]
            wanted = any(cov for _, cov in self.subscribers)
            if self.subscribers:  # the estimates (and covariances) only when someone listens
                poses = {self.names[r]: self._pose(r, wanted) for r in changed}
            else:
                poses = {}
            update = LiveUpdate(
                i,
                self.graph.steps[i][0],
                poses,
                len(self.graph.steps[i][1]),
                _time.perf_counter() - t0,
                _time.process_time() - cpu0,
            )
            every = self.checkpoint_every
            if self.checkpoint_path is not None and every and self.solver.done % every == 0:
                self.write_checkpoint()
            for callback, covariance in self.subscribers:
                try:
                    callback(
                        update
                        if covariance or not wanted
                        else replace(
                            update,
                            poses={n: replace(p, covariance=None) for n, p in poses.items()},
                        )
                    )
                except Exception as exc:  # the team goes on; raised after (`push`, `finish`)
                    self.callback_errors.append(exc)

    def _refactor(self, exc: Exception, i: int) -> None:
        """Cholesky found the system indeterminate: the pass again with QR from the first step
        (`team_graph.solve` does the same for a whole run)."""
        if self.graph.config.factorization == "QR":
            raise exc
        self.graph.config = replace(self.graph.config, factorization="QR")
        self.solver = None
        for j in range(i + 1):
            self._solver().step(j)
        self.solver_note = f"QR factorization (Cholesky failed: {exc})"

    def _done(self) -> int:
        """Graph steps solved."""
        return 0 if self.solver is None else self.solver.done

    def _solver(self) -> SideBySide:
        """The online passes (`solver`), made now if not yet: one per start, the guess and
        the alternatives of robots placed by a guess so far."""
        if self.solver is None:
            guessed = self.graph.guessed_alternatives
            times = start_times(guessed, self.graph.guessed_alternative_times)
            self.solver = SideBySide(self.graph, "online", [None, *guessed], times=times)
        return self.solver

    def _pose(self, r: int, covariance: bool) -> RobotPose:
        best = self.solver.best
        k, _ = best.latest[r]
        key = pose_key(r, k)
        session = best.session
        pose = session.estimate([key]).atPose3(key)
        cov = session.marginal_covariance(key) if covariance else None
        return RobotPose(float(self.graph.node_times[r][k]), k, pose, cov)


def live_builder(setup: LiveSetup, skips: SkipReport) -> tuple:
    """(the builder of the team's route, the tables it takes: `coverage.route`): `LiveGraph`
    for wheel-odometry robots, `event_rows.EventRows` for event-clocked ones."""
    tables = setup.tables or {}
    if route(setup.run, tables) == "event":
        from graphloc.live.event_rows import EventRows

        return EventRows(setup, tables, skips), tables_of("event")
    return LiveGraph(setup.run, setup.config, setup.start_time), tables_of("wheel")


def _plain(value):
    """A row's value as JSON takes it (a number or text)."""
    if isinstance(value, (bool, np.bool_)):
        return str(value)
    if isinstance(value, (int, float, str)):
        return value
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    return str(value)


def _item_time(item) -> float:
    """The time of a handler's item (`datasets.log_rows.TABLE_HANDLERS`)."""
    if isinstance(item, PointMeasurement):
        return float(item.time)
    return float(item[1][0])  # (robot, (time, ...)): odometry, planar ground truth
