"""`LiveRun`: one live run -- a source's rows pushed into a `graphloc.LiveTeam` as they arrive,
each update's poses out to the sinks and the status line, until a stop or `idle` seconds
without a row -- with its per-update log and latencies (docs/live.md); `graphloc live` is a
thin verb over it. `StatusLine`: its progress on the terminal."""

from __future__ import annotations

import collections
import time
from dataclasses import dataclass, field

import numpy as np

UPDATE_COLUMNS = (
    "step",
    "time",
    "robot",
    "trigger_robot",
    "trigger_table",
    "trigger_line",
    "arrived_s",
    "ready_s",
    "taken_s",
    "pushed_s",
    "sent_s",
    "step_s",
    "step_cpu_s",
)


def robot_poses(update) -> dict:
    """robot -> (time, gtsam.Pose3, 6x6 covariance) of a LiveUpdate's poses."""
    return {name: (p.time, p.pose, p.covariance) for name, p in update.poses.items()}


@dataclass
class LiveRun:
    team: object
    source: object
    sinks: list = field(default_factory=list)  # .publish(poses) / LiveView.show(poses, time)
    status: object | None = None  # StatusLine
    recorder: object | None = None  # graphloc.live.record.LogRecorder
    latencies: list = field(default_factory=list)  # [s] trigger's arrival -> poses out
    updates: list = field(default_factory=list)  # UPDATE_COLUMNS rows
    pushed: int = 0
    # (robot, table, line) of rows the team holds already (resumed from a checkpoint): a
    # source that reads them again (a log's tail) does not push them twice
    seen: set = field(default_factory=set)

    def __post_init__(self):
        # (robot, table, line, arrival, taken from the source, push began) of the row pushed
        self._trigger = None
        self.team.subscribe(self._on_update)

    def _on_update(self, update) -> None:
        ready = time.perf_counter()  # the update's poses and covariances computed
        poses = robot_poses(update)
        for sink in self.sinks:
            if hasattr(sink, "show"):
                sink.show(poses, update.time)
            else:
                sink.publish(poses)
        sent = time.perf_counter()
        nan = float("nan")
        robot, table, line, arrived, taken, pushed = self._trigger or ("", "", -1, nan, nan, nan)
        if self._trigger is not None:
            self.latencies.append(sent - arrived)
        for name, (t, _, _) in poses.items():
            self.updates.append(
                (update.step, t, name, robot, table, line, arrived, ready)
                + (taken, pushed, sent, update.latency_s, update.cpu_s)
            )
        if self.status is not None:
            self.status.add_update(update.latency_s, poses)

    def skipped(self) -> int:
        return self.source.skips.total + self.team.skips.total

    def push(self, rows, taken: float | None = None) -> None:
        """Rows (receive time, robot, table, row) into the recorder and the team; `taken`: when
        the run loop got them from the source (perf_counter s; default now)."""
        taken = time.perf_counter() if taken is None else taken
        if self.recorder is not None:
            self.recorder.write([r[1:] for r in rows])
        for arrived, robot, table, row in rows:
            if table == "groundtruth" or (robot, table, row.get("line")) in self.seen:
                continue
            line = row.get("line", -1)
            self._trigger = (robot, table, line, arrived, taken, time.perf_counter())
            self.team.push(robot, table, row)
            self._trigger = None  # updates at the end (finish) have no trigger
            self.pushed += 1
        if self.status is not None:
            self.status.add_rows([r[2] for r in rows])

    def latency_summary(self) -> dict:
        """p50 / p95 / max [s] of the end-to-end latencies (empty before an update)."""
        import numpy as np

        lat = np.asarray(self.latencies)
        if not len(lat):
            return {}
        return {
            k: float(np.percentile(lat, q)) for k, q in (("p50", 50), ("p95", 95), ("max", 100))
        }

    def run(self, stop=lambda: False, idle: float | None = None, poll: float = 0.05) -> str:
        """Until `stop()` ("stopped") or `idle` s after the last row ("idle"; not before the
        first row)."""
        last = None
        while True:
            if stop():
                return "stopped"
            rows = self.source.poll(poll)
            taken, now = time.perf_counter(), time.monotonic()
            if rows:
                last = now
                self.push(rows, taken)
            elif idle is not None and last is not None and now - last >= idle:
                return "idle"
            if self.status is not None:
                self.status.show(self.skipped())


class StatusLine:
    """A live run's progress on one terminal line (rows per second per table, iSAM2 step
    latency, largest position sigma, rows skipped) and the same as numbers (`summary`)."""

    def __init__(self, enabled: bool = True, window: float = 5.0, every: float = 0.5):
        from tqdm import tqdm

        self.window, self.every = window, every
        self.bar = tqdm(bar_format="{desc}", disable=not enabled, leave=True)
        self._arrivals: dict = collections.defaultdict(collections.deque)  # table -> times
        self.rows: collections.Counter = collections.Counter()
        self.latencies: list[float] = []
        self.sigma = 0.0
        self._shown = -np.inf

    def add_rows(self, tables, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        for table in tables:
            self._arrivals[table].append(now)
            self.rows[table] += 1

    def add_update(self, latency_s: float, poses: dict) -> None:
        """One iSAM2 update: its latency and the robots' (time, Pose3, covariance)."""
        self.latencies.append(float(latency_s))
        sig = [
            np.sqrt(np.linalg.eigvalsh(np.asarray(c)[3:, 3:]).max()) for _, _, c in poses.values()
        ]
        self.sigma = float(max(sig, default=0.0))

    def rates(self, now: float) -> dict:
        out = {}
        for table, times in self._arrivals.items():
            while times and times[0] < now - self.window:
                times.popleft()
            out[table] = len(times) / self.window
        return out

    def show(self, skipped: int, now: float | None = None, force: bool = False) -> None:
        now = time.monotonic() if now is None else now
        if not force and now - self._shown < self.every:
            return
        self._shown = now
        rates = " ".join(f"{t} {r:.0f}/s" for t, r in sorted(self.rates(now).items())) or "no rows"
        last = self.latencies[-100:]
        lat = (
            f"step {1e3 * np.median(last):.1f} ms (max {1e3 * max(last):.1f})"
            if last
            else "no update yet"
        )
        self.bar.set_description_str(
            f"live: {rates} | {len(self.latencies)} updates, {lat} | "
            f"sigma max {100 * self.sigma:.1f} cm | {skipped} skipped",
            refresh=True,
        )

    def summary(self) -> dict:
        lat = np.asarray(self.latencies)
        stats = (
            {k: float(np.percentile(lat, q)) for k, q in (("p50", 50), ("p95", 95), ("max", 100))}
            if len(lat)
            else {}
        )
        return {"rows": dict(self.rows), "updates": len(lat), "step_latency_s": stats}

    def close(self) -> None:
        self.bar.close()
