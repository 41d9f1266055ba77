"""Live use: a running team's rows pushed as they arrive, one iSAM2 update per completed time
step (`LiveTeam`, `team`); the incremental team graph behind it (`builder.LiveGraph`); a
recorded run replayed through it in time order (`replay_live`, `replay`). Sources and sinks of
`graphloc live` (each imported on use; ROS 2 and the view need `graphloc[live]`): a log
directory being written (`tail`), ROS 2 topics in and poses out over Cyclone DDS (`ros2`,
`ros2_types`, `topics`, `publish`), a ROS 2 run recorded as a log (`record`), the Foxglove view
(`view`), the status line (`status`) and the run loop (`pipeline`)."""

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
