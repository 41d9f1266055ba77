"""`StatusLine`: a live run's progress on one terminal line (rows per second per table, iSAM2 step
latency, largest position sigma, rows skipped) and the same as numbers (`summary`)."""

from __future__ import annotations

import collections
import time

import numpy as np


class StatusLine:
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
