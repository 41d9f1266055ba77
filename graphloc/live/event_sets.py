"""A candidate set into `live.events.EventGraph` once its poses are final (`take_set`): one
rule per (observer, target) stream (docs/design_team_graph.md, "Candidate sets")."""

from __future__ import annotations

from graphloc.keys import pose_key
from graphloc.live.event_camera import mixture_set
from graphloc.live.event_placement import seed_robot, start_variants, stream_placement
from graphloc.pipelines.team_graph.candidates import (
    StreamTracker,
    set_factors,
)


def take_set(events, n: int, o) -> None:
    """Set n (`o`, a `graphloc.run.CandidateObservation`) of `events`' run."""
    run, r, ti = events.run, o.robot, o.target
    if run.robots[ti].initial_pose is None:
        if run.robots[r].initial_pose is not None or o.candidates.source == "circle":
            # a placed observer (circles: a camera, held until it is placed): max-mixtures
            return mixture_set(events, n, o)  # (`live.event_camera`)
        key = (r, ti)  # counted at the end, one skip per stream (`events.record_graph`)
        events.unplaced_sets[key] = events.unplaced_sets.get(key, 0) + 1
        return
    key = (r, ti, o.pixels is not None)
    if key not in events.streams:
        tracker = StreamTracker(run, events.config, r, ti, o.pixels is not None)
        events.streams[key] = [tracker, [], len(events.streams) + len(events.mixtures)]
    tracker, obs, index = events.streams[key]
    obs.append((n, o))
    clock, step_rel = events.clock, events.graph.step_rel
    tracked = tracker.add(n, o, clock.nearest(r, o.time), clock.nearest(ti, o.time), step_rel)
    if tracked is None:
        return
    pixels, config = tracker.out.pixel_route, events.config
    made = set_factors(run, config, clock.node_times, tracked, pixels, events.marker_points)
    events.skips.merge(made.skips)
    events.marker_points.update(made.marker_points)
    events.graph.initial.update(made.marker_points)
    for point, target, kt, local in made.frame_points:
        events.graph.frame_points[point] = (pose_key(target, kt), local)
    for j, (t, f, kind) in enumerate(made.factors):
        events.pending.add(t, (4, index, len(obs), j), f, kind)
    _place(events, tracker, tracked)


def _place(events, tracker, tracked) -> None:
    """The observer's placement by one tracked set (docs/design_team_graph.md, "The event route:
    causality and placement"): a decided set, a registration from the stream's hypotheses, or a
    pixel stream's guess at its `guess_after_sets`-th set (at its last when the run ends sooner),
    every candidate of that set a hypothesis."""
    r, pixels = tracked.observation.robot, tracker.out.pixel_route
    robot = events.robots[r]
    if tracked.decided and not (pixels and robot.placed):
        pose = tracked.bodies[tracked.update.committed]
        seed_robot(events.graph, events.config, robot, tracked.k, pose)
    events.links.place(r, tracker.out.tentative)
    # the run ended (`EventGraph.finish`) with no set of this observer left: the stream's last
    # set is the guess's too, whatever its count (a short run)
    ended = robot.finished and not any(q.robot == r for _, q in events.queue)
    enough = len(tracker.out.sets) >= events.config.guess_after_sets
    if pixels and not robot.placed and (enough or ended):
        seed_robot(events.graph, events.config, robot, tracked.k, stream_placement(tracked))
        starts = [(tracked.k, body) for body in tracked.bodies]
        start_variants(events.graph, events.config, robot, starts)
