"""What a finished `live.events.EventGraph` records in its `TeamGraph`: every stream's set outcomes
in the order the streams began (tracked and max-mixture streams alike), the sections' skips (the
point measurements' too; the sets of a target without an initial pose seen by an observer without
one: one `target_unplaced` skip per stream), the alternative placements (pixel streams', resected
robots') and the graph's counts."""

from __future__ import annotations

from graphloc.live.event_placement import alternative_placements
from graphloc.pipelines.team_graph.graph import count_graph


def record_graph(events) -> None:
    """Decisions, skips, alternatives and counts of `events` (an `EventGraph` whose rows are
    all in) into its graph."""
    graph = events.graph
    tracked = list(events.streams.values())
    ordered = sorted(
        [(i, t.out.outcomes, t.out.skips) for t, _, i in tracked]
        + [(i, t.outcomes, t.made.skips) for t, i in events.mixtures.values()],
        key=lambda item: item[0],
    )
    graph.decisions = [d for _, outcomes, _ in ordered for d in outcomes]
    for _, _, skips in ordered:
        graph.skips.merge(skips)
    robots = events.run.robots
    for (r, ti), n in events.unplaced_sets.items():
        graph.skips.add(
            "target_unplaced",
            f"robot {robots[r].name}: {n} candidate sets on robot {robots[ti].name}: neither "
            f"has an initial pose (no max-mixture places one through the other)",
            n,
        )
    graph.skips.merge(events.features.tracks.made.skips)
    graph.skips.merge(events.skips)
    points = events.points.builder
    graph.skips.merge(points.made.skips)
    streams = [tracker.out for tracker, _, _ in tracked]
    alternative_placements(graph, events.config, events.robots, streams, points.sensors.poses)
    count_graph(
        graph,
        points,
        sum(len(r.times) for r in events.robots if r.seed is not None),
        candidate_sets=len(events.arrived),
        marker_points=len(events.marker_points),
        committed_sets=sum(d.committed >= 0 for d in graph.decisions),
        feature_tracks=len(events.features.tracks.tracks),
    )


def unplaced_robots(events) -> None:
    """Robots nothing placed by the end of `events` (an `EventGraph` whose rows are all in):
    each a counted skip `unanchored_robot` naming why (its factors stay held)."""
    graph = events.graph
    for robot in events.robots:
        if robot.seed is not None:
            continue
        graph.anchored_from.pop(robot.r, None)
        if not len(robot.times):  # no rows: no poses
            continue
        why = (
            "nothing placed it (no decided candidate set, no marker-pixel set, no placement "
            "by mutual bearings, resection or scan registration)"
        )
        events.skips.add(
            "unanchored_robot",
            f"robot {robot.robot.name}: {why}; its {len(robot.times)} poses are left out",
            len(robot.times),
        )
