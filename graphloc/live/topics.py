"""`LiveTopics`: messages of a topics file's topics, as they arrive, -> rows of the team's
tables through `graphloc import`'s converter (`datasets.rosbag_messages`), row by row; bad
messages are counted skips named by topic and index (docs/rosbag.md, "Skips")."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from graphloc.datasets.rosbag_messages import PoseChain, message_rows
from graphloc.datasets.rosbag_topics import TopicsFile
from graphloc.textio import SkipReport
from graphloc.records import columns

# the TUM columns of a groundtruth row (docs/log_format.md)
GROUNDTRUTH_COLUMNS = ("time", "x", "y", "z", "qx", "qy", "qz", "qw")


@dataclass
class LiveTopics:
    """Converter of one live source's messages (`topics`: the import's topics file)."""

    topics: TopicsFile
    source: str = "ros2"  # names the source in skip messages
    scans_dir: Path | None = None  # where clouds become ROBOT/scans/SENSOR_NNNNNN.ply
    skips: SkipReport = field(default_factory=SkipReport)

    def __post_init__(self):
        self._index = {t: 0 for t in self.topics.topics}
        self._chains = {
            t: PoseChain(self._where(t), m, self.skips)
            for t, m in self.topics.topics.items()
            if m.table == "relative_pose3"
        }

    def _where(self, topic: str) -> str:
        return f"{self.source}: topic '{topic}'"

    def rows(self, topic: str, msgtype: str, msg) -> list[tuple[str, str, dict]]:
        """(robot, table, row) of one message of `topic` (a mapped topic), in arrival order."""
        m = self.topics.topics[topic]
        i = self._index[topic]
        self._index[topic] += 1
        if m.table == "relative_pose3":
            row = self._chains[topic].add(i, msgtype, msg)
            got = [] if row is None else [row]
        else:
            got = message_rows(self._where(topic), m, i, msgtype, msg, self.skips)
        if m.table == "scans":
            got = [(t, s, self._scan(m.robot, s, i, pts)) for t, s, pts in got]
        names = GROUNDTRUTH_COLUMNS if m.table == "groundtruth" else columns(m.table)
        return [(m.robot, m.table, dict(zip(names, row))) for row in got]

    def _scan(self, robot: str, sensor: str, index: int, pts) -> str:
        from graphloc.datasets.rosbag import write_scan

        if self.scans_dir is None:
            raise ValueError(f"{self._where('?')}: a scans topic needs a folder for its clouds")
        return write_scan(self.scans_dir, robot, sensor, index, pts)
