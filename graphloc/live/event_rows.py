"""`EventRows`: an event-clocked team's checked rows into its `events.EventGraph`, with the
interface `LiveTeam` drives; marker, candidate, ellipse and feature rows held until the window
passes their time, then made into sets and pixels by the loader's own front ends.
`build_events`: a loaded run's graph on the event route. `ScanFeed`: the `scans` rows through
KISS-ICP as they arrive (seed 004 Sec. II-B), one `mapping.odometry.ScanOdometry` per (robot,
scanner), each step the relative pose the loader makes of it (`log_observations.scan_step`); a
scan that cannot be used is a counted skip."""

from __future__ import annotations

import heapq
from dataclasses import replace

import gtsam
import numpy as np

from graphloc.datasets.camera_tables import (
    ellipse_observations,
    feature_observations,
    single_tracks,
)
from graphloc.datasets.log_observations import (
    candidate_observations,
    marker_observations,
    scan_step,
)
from graphloc.textio import Sink, SkipReport, confined
from graphloc.keys import decode
from graphloc.live.coverage import NotLiveError, max_mixtures_possible, run_tables
from graphloc.live.events import EventGraph
from graphloc.live.setup import empty_run
from graphloc.live.wheel_steps import WheelSteps, skip_relative, wheel_motions
from graphloc.pipelines.team_graph.config import GraphConfig
from graphloc.pipelines.team_graph.graph import TeamGraph, factor_keys
from graphloc.run import ScanObservation, TeamRun

RELATIVE = ("relative_pose", "relative_pose3")
POINT_TABLES = ("range", "bearing", "range_bearing")


class EventRows:
    """The rows of an event-clocked team (module docstring); `setup`: its `LiveSetup`,
    `tables`: each robot's tables by name, `skips`: where refused rows and sets are counted."""

    def __init__(self, setup, tables: dict, skips):
        run = setup.run
        self.setup, self.robots = setup, run.robots
        self.wheels = {  # moving robots with wheel odometry (a static robot's is not used)
            r: WheelSteps(r, run, setup.config)
            for r, robot in enumerate(run.robots)
            if "odometry" in tables.get(robot.name, ()) and not robot.static
        }
        stamped = set(self.wheels) | {
            r
            for r, robot in enumerate(run.robots)
            if set(RELATIVE + ("scans",)) & set(tables.get(robot.name, ()))
        }
        observers = {
            r
            for r, robot in enumerate(run.robots)
            if {"markers", "candidates", "ellipses"} & set(tables.get(robot.name, ()))
        }
        camera = any({"features", "ellipses"} & set(t) for t in tables.values())
        camera = camera or max_mixtures_possible(run, tables)
        self.events = EventGraph(
            run, setup.config, setup.start_time, stamped, observers, camera, set(self.wheels)
        )
        self.graph = self.events.graph
        self.sink = Sink("skip", skips)
        self.sensors = [list(robot.sensors) for robot in run.robots]
        self.index = {robot.name: r for r, robot in enumerate(run.robots)}
        self.markers: list = []  # (time, observer, sensor index, target, marker, u, v, row)
        self.candidates: dict = {}  # (time, observer, sensor, target) -> [record]
        self.ellipses: list = []  # (observer, target, record, where)
        self.pixels: list = []  # features: (robot, record)
        self.motions: list = []  # relative poses and scan steps, in arrival order
        self.held: list = []  # ... waiting for the run's start (`_start`)
        self.points: list = []
        self.waiting: list = []  # point rows not in the graph yet, in arrival (time) order
        self.scans = ScanFeed(run, setup.manifest.root, skips, SkipReport())

    def velocity(self, r: int, rows) -> None:
        """Wheel-odometry rows (time, v, omega), one (3,) or many (N,3), of robot r: the grid
        steps they complete into the graph as relative poses."""
        wheel = self.wheels.get(r)
        if wheel is None:
            if self.robots[r].static:  # its one pose is at the start (`LiveGraph` alike)
                return
            raise NotLiveError(
                f"robot {self.robots[r].name}: wheel odometry, but its manifest has no "
                f"odometry table (its pose times are at its relative poses or measurements)"
            )
        wheel.add(rows)
        start = self._start()
        if start is not None:
            for _, m in wheel.steps(start):
                self.events.motion(m)

    def _start(self, final: bool = False) -> float | None:
        """The run's start once known: the manifest's, else the latest first odometry row of the
        wheel robots once each has one (`final`: of those that have one), else the event route's
        own; the held relative poses, then the wheel steps so far, go in."""
        events = self.events
        if events.start is not None or not self.wheels:
            return events.start
        firsts = [w.first for w in self.wheels.values() if w.first is not None]
        if not firsts or (len(firsts) < len(self.wheels) and not final):
            return None
        events.start = max(firsts)
        for m in self.held:
            events.motion(m)
        self.held = []
        for wheel in self.wheels.values():
            for _, m in wheel.steps(events.start):
                events.motion(m)
        return events.start

    def _motion(self, m, table: str) -> None:
        """A relative pose (a row or a scan step) into the graph, or held for the start; a
        wheel robot's is a counted skip (`wheel_steps.skip_relative`)."""
        if m.robot in self.wheels:
            skip_relative(self.sink.report, self.robots[m.robot], f"{table!r} row")
            return
        self.motions.append(m)
        if self.wheels and self._start() is None:
            self.held.append(m)
        else:
            self.events.motion(m)

    def point(self, item) -> None:
        """A checked row: (robot index, (time, table, item))."""
        r, (t, table, row) = item
        if table in RELATIVE:
            self._motion(row, table)
        elif table == "scans":
            made = self.scans.add(r, *row)
            if made is not None:
                scan, step = made
                if step is not None:
                    self._motion(step, table)
                self.events.links.scan(scan)
        elif table == "markers":
            sensor = self.sensors[r].index(row.sensor)
            target = self.index[row.target]
            self.markers.append((t, r, sensor, target, row.marker, row.u, row.v, row.line))
        elif table == "candidates":
            key, record = row
            self.candidates.setdefault(key, []).append(record)
        elif table in POINT_TABLES:  # with the sets and pixels of its time (`_sets`)
            self.points.append(row)
            self.waiting.append(row)
        elif table == "ellipses":
            self.ellipses.append(row)
        elif table == "features":
            self.pixels.append(row)
        else:
            raise NotLiveError(f"table {table!r} is not live in an event-clocked team")

    def advance(self, watermark: float) -> list:
        self._sets(watermark)
        return self.events.advance(watermark)

    def finish(self) -> list:
        self._start(final=True)
        for m in self.held:  # no wheel robot had a row: the event route's own start
            self.events.motion(m)
        self.held = []
        self._sets(np.inf)
        return self.events.finish()

    def run_so_far(self):
        """The run of the rows that arrived (the loaded run's odometry, motions and candidate
        sets)."""
        events = self.events
        start = np.nan if events.start is None else float(events.start)
        velocity = [np.zeros((0, 3)) for _ in self.robots]
        for r, wheel in self.wheels.items():
            velocity[r] = wheel.rows.view.copy()
        return replace(
            self.setup.run,
            start_time=start,
            velocity=tuple(velocity),
            motions=tuple(self.motions),
            observations=tuple(events.arrived),
            points=tuple(self.points),
            features=tuple(events.features.arrived),
            scans=tuple(self.scans.scans),
        )

    def _where(self, r: int, row) -> str:
        return f"robot {self.robots[r].name!r}, table 'features', row {row.line}"

    def _sets(self, watermark: float) -> None:
        """The images, logged sets and ellipses before `watermark` as candidate sets in the loader's
        order, the feature pixels and point rows before it: into the graph in time order."""
        manifest, noise = self.setup.manifest, self.setup.noise
        out: list = []
        done = [m for m in self.markers if m[0] < watermark]
        if done:
            self.markers = [m for m in self.markers if m[0] >= watermark]
            names = ("time", "robot", "sensor", "target", "marker", "u", "v", "line")
            types = (float, np.int32, np.int32, np.int32, np.int32, float, float, np.int64)
            columns = {
                name: np.array(values, dtype=kind)
                for name, kind, values in zip(names, types, zip(*done))
            }
            sets, _ = marker_observations(columns, self.robots, manifest, noise, self.sink)
            out += sets
        keys = [key for key in self.candidates if key[0] < watermark]
        if keys:
            groups = {key: self.candidates.pop(key) for key in keys}
            out += candidate_observations(groups, self.robots, noise, manifest, self.sink)
        ellipses = [e for e in self.ellipses if e[2].time < watermark]
        if ellipses:
            self.ellipses = [e for e in self.ellipses if e[2].time >= watermark]
            out += ellipse_observations(ellipses, self.robots, manifest, self.sink)
        out.sort(key=lambda o: (o.time, o.robot))
        features: list = []
        pixels = [p for p in self.pixels if p[1].time < watermark]
        if pixels:  # the loader's front end: one image's pixels together
            self.pixels = [p for p in self.pixels if p[1].time >= watermark]
            pixels = single_tracks(pixels, manifest, self.sink, self._where)
            features = feature_observations(pixels, self.robots, manifest, noise)
        points = [m for m in self.waiting if m.time < watermark]
        self.waiting = self.waiting[len(points) :]
        # at one time: sets, pixels, then point rows (`build_events`)
        sets = ((o.time, 0, o) for o in out)
        pixels = ((f.time, 1, f) for f in features)
        rows = heapq.merge(sets, pixels, ((m.time, 2, m) for m in points), key=lambda e: e[:2])
        take = (self.events.observation, self.events.feature, self.events.point)
        for _, kind, row in rows:
            take[kind](row)


def build_events(run: TeamRun, config: GraphConfig, steps=None) -> TeamGraph:
    """A loaded run's graph built by `EventGraph`: its relative poses, wheel robots' grid steps,
    scans, candidate sets, pixels and point measurements merged in time order. steps: None, or a
    list that gets the steps each row completed (`advance` at its time: the live order)."""
    wheel = wheel_motions(run, config)
    stamped = {m.robot for m in run.motions} | {m.robot for _, m in wheel}
    observers = {o.robot for o in run.observations}
    camera = bool(run.features) or any(o.candidates.source == "circle" for o in run.observations)
    camera = camera or max_mixtures_possible(run, run_tables(run))
    wheels = {m.robot for _, m in wheel}
    live = EventGraph(empty_run(run), config, run.start_time, stamped, observers, camera, wheels)
    for m in run.motions:
        if m.robot in wheels:
            skip_relative(live.graph.skips, run.robots[m.robot])
    # each table in time order (a robot's relative poses and its scans' KISS-ICP steps are
    # two tables: merged by end time, as a live team's window orders them); a wheel robot's
    # grid step at the odometry row that completes it
    relative = ((max(m.t0, m.t1), 0, i, m) for i, m in enumerate(run.motions))
    motions = sorted(
        [e for e in relative if e[3].robot not in wheels]
        + [(t, 0, len(run.motions) + i, m) for i, (t, m) in enumerate(wheel)]
    )
    scans = sorted((s.time, 1, i, s) for i, s in enumerate(run.scans))
    sets = sorted((o.time, 2, i, o) for i, o in enumerate(run.observations))
    pixels = sorted((f.time, 3, i, f) for i, f in enumerate(run.features))
    points = sorted((m.time, 4, i, m) for i, m in enumerate(run.points))
    take = (live.motion, live.links.scan, live.observation, live.feature, live.point)
    rows = heapq.merge(motions, scans, sets, pixels, points, key=lambda e: e[:3])
    for t, kind, _, row in rows:
        take[kind](row)
        if steps is not None:
            steps.append(live.advance(t))
    done = live.finish()
    if steps is not None:
        steps.append(done)
    live.graph.run = run
    _drop_unplaced(live.graph, {r.r for r in live.robots if r.seed is None})
    return live.graph


def _drop_unplaced(graph: TeamGraph, robots: set) -> None:
    """The factors on poses of `robots` (nothing placed them: `EventGraph.finish` counted them
    `unanchored_robot`) out of the graph's steps, as the live team's online pass holds them to
    the end; a batch solve has no initial values for them."""
    if not robots:
        return
    steps, types = [], []
    for t, group in graph.steps:
        kept = [
            (f, kind)
            for f, kind in group
            if not any(
                decode(key)[0] in ("x", "s") and decode(key)[1] in robots for key in factor_keys(f)
            )
        ]
        steps.append((t, kept))
        types += [kind for _, kind in kept]
    graph.steps, graph.factor_types = steps, types
    counts = {k: v for k, v in graph.counts.items() if not k.startswith("factors_")}
    counts.update({f"factors_{name}": types.count(name) for name in sorted(set(types))})
    graph.counts = counts


class ScanFeed:
    """The scanners of a live team (`run`: its robots and their sensors; `root`: the run
    directory the rows' paths are in); `add(r, key, row)` -> (the scan's `ScanObservation`, the
    relative pose -- a `graphloc.run.Motion` -- it makes, None for a first scan), or None (a
    counted skip)."""

    def __init__(self, run, root, skips, notes):
        self.run, self.root = run, root
        self.skips, self.notes = skips, notes
        self.odometry: dict = {}  # (robot, sensor) -> (ScanOdometry, time of its last scan)
        self.scans: list = []  # ScanObservation of every scan used, in arrival order

    def add(self, r: int, key: tuple, row):
        """Robot r's released `scans` row (`key`: (robot, sensor), its handler's item)."""
        from graphloc.mapping.io import read_scan
        from graphloc.mapping.odometry import ScanOdometry

        robot = self.run.robots[r]
        where = f"robot {robot.name!r}, table 'scans', row {row.line}: field 'path'"
        try:
            path = self.root / confined(self.root, row.path, where)
            points, dropped = read_scan(path, self.notes)
        except ValueError as exc:
            reason = "path_outside_run" if where in str(exc) else "bad_scan"
            message = str(exc) if reason == "path_outside_run" else f"{where}: {exc}"
            self.skips.add(reason, message)
            return None
        except OSError as exc:
            self.skips.add("bad_scan", f"{where}: {row.path}: {exc.strerror or exc}")
            return None
        if dropped:
            self.skips.add(
                "scan_points_nonfinite", f"{where}: {dropped} non-finite points", dropped
            )
        T_bs, params = robot.sensors[row.sensor]
        scan = ScanObservation(row.time, r, gtsam.Pose3(T_bs), path)
        self.scans.append(scan)
        if key not in self.odometry:
            self.odometry[key] = (ScanOdometry(), None)
        odometry, last = self.odometry[key]
        step = odometry.add(points)
        self.odometry[key] = (odometry, row.time)
        if step is None:
            return scan, None
        return scan, scan_step(r, T_bs, params, last, row.time, step)
