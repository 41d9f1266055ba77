"""`LogRecorder`: the rows of a live ROS 2 source written as a log directory as they arrive
(`graphloc live --ros2 --out DIR`: the import's manifest, then each row appended and flushed),
so that `graphloc online DIR/log` replays what arrived; an existing log is continued."""

from __future__ import annotations

from pathlib import Path

from graphloc.datasets.rosbag import table_path, write_log_manifest
from graphloc.datasets.rosbag_topics import TopicsFile
from graphloc.manifest import MANIFEST, read_manifest
from graphloc.records import columns
from graphloc.live.topics import GROUNDTRUTH_COLUMNS
from graphloc.log_writer import cell
from graphloc.names import out_path


def live_tables(tf: TopicsFile) -> dict:
    """robot -> {table: relative path} of every table the topics file's topics fill."""
    out: dict = {}
    for m in tf.topics.values():
        out.setdefault(m.robot, {})[m.table] = table_path(m.robot, m.table)
    return out


def check_live(tf: TopicsFile) -> None:
    """What a live ROS 2 source cannot do yet, as an error naming the topics file's field: the
    intrinsics from a CameraInfo topic and the extrinsics from tf (`camera_info`, `frames`)
    arrive as messages, after the team is opened on its manifest; live, state them in the
    sensors' `params` / `extrinsics`."""
    for topic, m in tf.topics.items():
        if m.camera_info is not None:
            raise ValueError(
                f"{tf.path}: topics['{topic}']: field 'camera_info' is read from a bag only; "
                "for graphloc live give the camera's fx, fy, cx, cy, width, height in its params"
            )
    if tf.frames:
        raise ValueError(
            f"{tf.path}: field 'frames' is read from a bag's tf only; for graphloc live give "
            "each sensor's 'extrinsics'"
        )


class LogRecorder:
    """The log directory `root` of a live ROS 2 run (module docstring)."""

    def __init__(self, tf: TopicsFile, root: Path):
        self.root = Path(root)
        self.tables = live_tables(tf)
        self.resumed = (self.root / MANIFEST).is_file()
        if self.resumed:
            have = {r.name: dict(r.tables) for r in read_manifest(self.root).robots}
            if have != self.tables:
                raise ValueError(
                    f"{self.root / MANIFEST}: a log of other topics ({have}); give another "
                    f"--out or the topics file it was recorded with"
                )
        else:
            self.root.mkdir(parents=True, exist_ok=True)
            meta = {"source": "ros2", "topics": str(tf.path)}
            write_log_manifest(tf, self.root, self.tables, meta, key="live")
        self._files = {}
        for robot, tables in self.tables.items():
            for table, rel in tables.items():
                path = out_path(self.root, *rel.split("/"))
                path.parent.mkdir(parents=True, exist_ok=True)
                new = not path.exists()
                fh = open(path, "a", newline="")
                if new and table != "groundtruth":
                    fh.write(",".join(columns(table)) + "\n")
                    fh.flush()
                self._files[(robot, table)] = fh

    def write(self, rows) -> None:
        """Append (robot, table, row) rows; each file flushed once."""
        touched = set()
        for robot, table, row in rows:
            fh = self._files[(robot, table)]
            if table == "groundtruth":
                fh.write(" ".join(cell(row[c]) for c in GROUNDTRUTH_COLUMNS) + "\n")
            else:
                fh.write(",".join(cell(row[c]) for c in columns(table)) + "\n")
            touched.add(fh)
        for fh in touched:
            fh.flush()

    def close(self) -> None:
        for fh in self._files.values():
            fh.close()
