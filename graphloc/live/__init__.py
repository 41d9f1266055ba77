"""Live use: a running team's rows pushed as they arrive (`LiveTeam`), a recorded run replayed
through it (`replay_live`, `run_rows`), and the sources and sinks of `graphloc live` (each
imported on use; ROS 2 and the view need `graphloc[live]`)."""

from graphloc.live.coverage import NotLiveError
from graphloc.live.replay import replay, run_rows
from graphloc.live.team import LiveTeam, LiveUpdate, RobotPose


def replay_live(source, options=None, window: float = 0.5, subscriber=None):
    """The run at `source` (a log or MRCLAM directory) pushed row by row into a new
    `LiveTeam`, in time order; returns the finished team (`team.finish()` is its result)."""
    team = LiveTeam.open(source, options, window)
    if subscriber is not None:
        team.subscribe(subscriber)
    replay(team, run_rows(source, options))
    team.finish()
    return team


__all__ = [
    "LiveTeam",
    "LiveUpdate",
    "NotLiveError",
    "RobotPose",
    "replay",
    "replay_live",
    "run_rows",
]
