"""What the live builder covers (`graphloc.live.builder.LiveGraph`): the tables it takes rows
of, and what keeps a run off it (`not_live`), with why -- the sections that need rows after
the step they shape."""

from __future__ import annotations

from graphloc.run import TeamRun

# the sections `LiveGraph` builds, and the tables it takes rows of
LIVE_TABLES = ("odometry", "range", "bearing", "range_bearing", "groundtruth")
# tables whose sections are not causal yet, and why (`not_live`)
NOT_LIVE = {
    "relative_pose": "event-clocked pose times (relative poses split at measurement times)",
    "relative_pose3": "event-clocked pose times (relative poses split at measurement times)",
    "markers": "candidate sets (P3P, the hypothesis trackers, placement by decisions)",
    "candidates": "candidate sets (the hypothesis trackers, placement by decisions)",
    "ellipses": "candidate sets (circle poses, the hypothesis trackers)",
    "features": "camera feature tracks (a track's point prior from all its pixels)",
    "scans": "KISS-ICP odometry and inter-robot scan registration",
}


class NotLiveError(ValueError):
    """A run that needs sections the live builder does not build yet (`not_live`)."""


def not_live(run: TeamRun, tables: dict) -> list[str]:
    """What keeps a run (its robots, and each robot's tables by name) off the live builder, one
    line each; empty: the run is live."""
    out = []
    for r, robot in enumerate(run.robots):
        for table in sorted(set(tables.get(robot.name, ())) & set(NOT_LIVE)):
            out.append(f"robot {robot.name}: table {table!r}: {NOT_LIVE[table]}")
        if robot.initial_pose is None:
            out.append(
                f"robot {robot.name}: no initial_pose: its placement (decided candidate sets, "
                f"mutual bearings, resection, scan registration) and alternative starts"
            )
        measured = sorted(set(tables.get(robot.name, ())) & {"range", "bearing", "range_bearing"})
        if robot.static and measured:
            out.append(
                f"robot {robot.name}: static, with tables {measured}: its measurements join its "
                f"one pose at the start (a step long past when they arrive)"
            )
        if not robot.static and "odometry" not in tables.get(robot.name, ()):
            out.append(
                f"robot {robot.name}: no odometry table: event-clocked pose times (poses at "
                f"its measurement times)"
            )
    return out


def run_tables(run: TeamRun) -> dict:
    """The tables a loaded run's rows came from, per robot name, as far as `not_live` asks."""
    tables: dict = {robot.name: set() for robot in run.robots}
    for r, robot in enumerate(run.robots):
        if len(run.velocity[r]):
            tables[robot.name].add("odometry")
    for m in run.motions:
        tables[run.robots[m.robot].name].add("relative_pose3")
    for p in run.points:
        tables[run.robots[p.robot].name].add(p.kind)
    for o in run.observations:
        tables[run.robots[o.robot].name].add("candidates")
    for f in run.features:
        tables[run.robots[f.robot].name].add("features")
    for s in run.scans:
        tables[run.robots[s.robot].name].add("scans")
    return tables
