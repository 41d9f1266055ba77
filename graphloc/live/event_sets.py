"""A candidate set into `live.events.EventGraph` once its poses are final (`take_set`): its
(observer, target) stream's `candidates.StreamTracker` (the decision uses the sets before it
only), the factors `candidates.stream_factors` makes of it -- a decided candidate's robust
prior, or a pixel stream's projection factors on a static target's marker points or, for a
moving target with an initial pose, on per-set marker points held on the target's pose
(`camera.moving_marker_factors`; their initial values from the target's pose once it has
one) --, then the observer's placement: its decided pose (a pixel stream: the first), or, for
a scanning observer, the inter-robot scan registration from the tracker's hypotheses
(`event_scans.ScanLinks.place`), or, for a pixel stream with no decision among its first
`GraphConfig.guess_after_sets` sets, the tracker's best guess at that set
(`event_placement.stream_placement`). A set of an unplaced target seen by a placed observer --
circles: by any camera, held until it is placed -- is a max-mixture set
(`live.event_camera.mixture_set`)."""

from __future__ import annotations

from graphloc.keys import pose_key
from graphloc.live.coverage import NotLiveError
from graphloc.live.event_camera import mixture_set
from graphloc.live.event_placement import seed_robot, stream_placement
from graphloc.pipelines.team_graph.candidates import (
    StreamDecisions,
    StreamTracker,
    stream_factors,
)


def take_set(events, n: int, o) -> None:
    """Set n (`o`, a `graphloc.run.CandidateObservation`) of `events`' run."""
    run, r, ti = events.run, o.robot, o.target
    key = (r, ti)
    if key in events.mixtures or (
        key not in events.streams
        and run.robots[ti].initial_pose is None
        and (run.robots[r].initial_pose is not None or o.candidates.source == "circle")
    ):  # a placed observer (circles: once placed), an unplaced target: max-mixtures
        # (`live.event_camera`)
        return mixture_set(events, n, o)
    if key not in events.streams:
        t = run.robots[ti]
        if t.initial_pose is None:
            raise NotLiveError(
                f"robot {run.robots[r].name}: candidate sets of {t.name}, which has no "
                f"initial_pose (an unplaced target: max-mixtures)"
            )
        if not t.static and o.pixels is None:
            raise NotLiveError(
                f"robot {run.robots[r].name}: candidate sets of the moving {t.name} without "
                f"marker pixels (between factors on both poses: not live yet)"
            )
        if any(k[0] == r for k in events.streams):
            raise NotLiveError(
                f"robot {run.robots[r].name}: candidate sets of two targets: the whole-run "
                f"route places it by its streams in order of their first set"
            )
        tracker = StreamTracker(run, events.config, r, ti, o.pixels is not None)
        events.streams[key] = [tracker, [], len(events.streams) + len(events.mixtures)]
    tracker, obs, index = events.streams[key]
    if (o.pixels is not None) != tracker.out.pixel_route:
        raise NotLiveError(
            f"robot {run.robots[r].name}: candidate sets of {run.robots[ti].name} with and "
            f"without marker pixels"
        )
    obs.append((n, o))
    clock, step_rel = events.clock, events.graph.step_rel
    tracked = tracker.add(n, o, clock.nearest(r, o.time), clock.nearest(ti, o.time), step_rel)
    if tracked is None:
        return
    one = StreamDecisions(r, ti, tracker.out.pixel_route, [tracked])
    made = stream_factors(run, events.config, clock, one, [(n, o)], events.marker_points)
    events.skips.merge(made.skips)
    events.marker_points.update(made.marker_points)
    events.graph.initial.update(made.marker_points)
    for point, target, kt, local in made.frame_points:
        events.graph.frame_points[point] = (pose_key(target, kt), local)
    for j, (t, f, kind) in enumerate(made.factors):
        events.pending_factor(t, (4, index, len(obs), j), f, kind)
    robot = events.robots[r]
    if tracked.decided and not (tracker.out.pixel_route and robot.placed):
        pose = tracked.bodies[tracked.update.committed]
        seed_robot(events.graph, events.config, robot, tracked.k, pose)
    events.links.place(r, tracker.out.tentative)
    if (
        tracker.out.pixel_route
        and not robot.placed
        and len(tracker.out.sets) >= events.config.guess_after_sets
    ):  # placed once, by a guess after `guess_after_sets` undecided sets (`stream_placement`)
        seed_robot(events.graph, events.config, robot, tracked.k, stream_placement(tracked))
