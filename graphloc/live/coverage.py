"""Which of the two live routes a run takes (`route`: the wheel route's `LiveGraph` or the
event route's `EventGraph`) and the tables each takes rows of."""

from __future__ import annotations

from graphloc.run import TeamRun

# the sections `LiveGraph` builds, and the tables it takes rows of
LIVE_TABLES = ("odometry", "range", "bearing", "range_bearing", "groundtruth")
# the tables whose rows make `EventGraph`'s route (`route` "event")
EVENT_ROWS = (
    "relative_pose",
    "relative_pose3",
    "scans",
    "markers",
    "candidates",
    "ellipses",
    "features",
)
# ... and all it takes: with the point measurements, wheel robots' odometry (`live.wheel_steps`)
EVENT_TABLES = EVENT_ROWS + ("odometry", "range", "bearing", "range_bearing", "groundtruth")


class NotLiveError(ValueError):
    """A row or table the live team cannot take as it comes (e.g. a table no route reads, a
    topic of the wrong table), named."""


def route(run: TeamRun, tables: dict) -> str:
    """ "wheel" (`LiveGraph`) for wheel-odometry robots with an initial pose and point measurements
    that route takes whole (`wheel_problems` finds nothing: MRCLAM), else "event" (`EventGraph`)."""
    named = set().union(*map(set, tables.values())) if tables else set()
    if named & set(EVENT_ROWS) or wheel_problems(run, tables):
        return "event"
    return "wheel"


def tables_of(kind: str) -> tuple:
    """The tables a route takes rows of."""
    return EVENT_TABLES if kind == "event" else LIVE_TABLES


def wheel_problems(run: TeamRun, tables: dict) -> list[str]:
    """What keeps a run off the wheel route (`LiveGraph`), one line each: tables of the event
    route, and the robots whose sections need rows after the step they shape there (the event
    route takes them: `route`)."""
    out = []
    for robot in run.robots:
        mine = set(tables.get(robot.name, ()))
        for table in sorted(mine & set(EVENT_ROWS)):
            out.append(f"robot {robot.name}: table {table!r} of the event route")
        if robot.initial_pose is None:
            out.append(
                f"robot {robot.name}: no initial_pose: its placement (decided candidate sets, "
                f"mutual bearings, resection, scan registration) and alternative starts"
            )
        measured = sorted(mine & {"range", "bearing", "range_bearing"})
        if robot.static and measured:
            out.append(
                f"robot {robot.name}: static, with tables {measured}: its measurements join its "
                f"one pose at the start (a step long past when they arrive)"
            )
        if not robot.static and "odometry" not in mine:
            out.append(
                f"robot {robot.name}: no odometry table: event-clocked pose times (poses at "
                f"its measurement times)"
            )
    return out


def set_targets(run: TeamRun, tables: dict) -> set:
    """The robots candidate sets see: a loaded run's targets; before any row, robots with a marker
    layout when some robot has a markers table, every robot when one has a candidates table."""
    if run.observations:
        return {o.target for o in run.observations if o.candidates.source != "circle"}
    named = set().union(*map(set, tables.values())) if tables else set()
    if "candidates" in named:
        return set(range(len(run.robots)))
    if "markers" in named:
        return {r for r, robot in enumerate(run.robots) if robot.markers is not None}
    return set()


def max_mixtures_possible(run: TeamRun, tables: dict) -> bool:
    """Whether candidate sets may become max-mixtures (an observer with an initial pose, a target
    without one): the graph is then a camera graph (`TeamGraph.camera`), known before its rows."""
    observers = [
        robot for robot in run.robots if {"markers", "candidates"} & set(tables.get(robot.name, ()))
    ]
    targets = set_targets(run, tables)
    return any(o.initial_pose is not None for o in observers) and any(
        run.robots[t].initial_pose is None for t in targets
    )


def run_tables(run: TeamRun) -> dict:
    """The tables a loaded run's rows came from, per robot name, as far as `route` asks."""
    tables: dict = {robot.name: set() for robot in run.robots}
    for r, robot in enumerate(run.robots):
        if len(run.velocity[r]):
            tables[robot.name].add("odometry")
    for m in run.motions:
        tables[run.robots[m.robot].name].add("relative_pose3")
    for p in run.points:
        tables[run.robots[p.robot].name].add(p.kind)
    for o in run.observations:
        circle = o.candidates.source == "circle"
        tables[run.robots[o.robot].name].add("ellipses" if circle else "candidates")
    for f in run.features:
        tables[run.robots[f.robot].name].add("features")
    for s in run.scans:
        tables[run.robots[s.robot].name].add("scans")
    return tables
