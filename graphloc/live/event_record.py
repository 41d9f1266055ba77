"""What a finished `live.events.EventGraph` records in its `TeamGraph`, as `build_graph` records
it: every stream's set outcomes in the order the streams began (tracked and max-mixture
streams alike), the sections' skips, the pixel streams' alternative placements and the graph's
counts."""

from __future__ import annotations

from graphloc.live.event_placement import alternative_placements


def record_graph(events) -> None:
    """Decisions, skips, alternatives and counts of `events` (an `EventGraph` whose rows are
    all in) into its graph."""
    graph = events.graph
    tracked = list(events.streams.values())
    ordered = sorted(
        [(i, t.out.outcomes, t.out.skips) for t, _, i in tracked]
        + [(i, t.out.outcomes, t.out.made.skips) for t, i in events.mixtures.values()],
        key=lambda item: item[0],
    )
    graph.decisions = [d for _, outcomes, _ in ordered for d in outcomes]
    for _, _, skips in ordered:
        graph.skips.merge(skips)
    graph.skips.merge(events.features.tracks.section.made.skips)
    graph.skips.merge(events.skips)
    alternative_placements(
        events.run,
        events.config,
        events.clock,
        graph,
        events.robots,
        [tracker.out for tracker, _, _ in tracked],
    )
    types = graph.factor_types
    graph.counts = {
        "robots": len(events.run.robots),
        "poses": sum(len(r.times) for r in events.robots if r.seed is not None),
        "candidate_sets": len(events.arrived),
        "marker_points": len(events.marker_points),
        "frame_marker_points": len(graph.frame_points),
        "sensor_poses": 0,
        "committed_sets": sum(d.committed >= 0 for d in graph.decisions),
        "landmark_anchors": 0,
        "feature_tracks": events.features.tracks.section.tracks,
        "steps": len(graph.steps),
        "excluded_by_option": 0,
        **{f"factors_{name}": types.count(name) for name in sorted(set(types))},
    }
