"""`ArcIntegrator`: the whole-run unicycle integration (the tests' reference:
`benchmarks.planar_factors.integrate_unicycle`) carried forward as velocity rows arrive (into a
`GrowingArray`); the running sums continued, so poses, steps and covariances are those
of one call over the whole run, bit for bit (tests/live/test_live.py)."""

from __future__ import annotations

import numpy as np

from graphloc.factors.odometry import VelocityNoise, _wrap, relative_poses, step_covariances


class ArcIntegrator:
    """One robot's dead reckoning from its first stamp (0, 0, 0) over its velocity samples
    (zero-order hold, `integrate_unicycle`). `samples` returns the (N,3) time, v, omega rows
    known so far (the caller's growing table); `advance(stamps)` needs every row up to the
    last of them."""

    def __init__(self, samples, noise: VelocityNoise, covariances: bool = True):
        self.samples, self.noise, self.covariances = samples, noise, covariances
        self.stamp: float | None = None
        self.state = (0.0, 0.0, 0.0)  # x, y and the unwrapped heading at `stamp`

    def advance(self, stamps) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Integrate to `stamps` (increasing, after the last stamp; the first call's first
        stamp is the origin): (K,3) poses (x, y, wrapped theta) at the new stamps, (K,3) steps
        from the stamp before each, (K,3,3) their covariances (`integrate_unicycle`'s)."""
        kf = np.asarray(stamps, dtype=float)
        if self.stamp is None:
            self.stamp = float(kf[0])
            kf = kf[1:]
            first = np.array([[0.0, 0.0, 0.0]])
            if not len(kf):
                return first, np.zeros((0, 3)), np.zeros((0, 3, 3))
        else:
            first = np.zeros((0, 3))
        kf = np.concatenate([[self.stamp], kf])
        table = self.samples()
        # the rows that act on [kf[0], kf[-1]): the last at or before kf[0] on (a slice, so a
        # call costs the rows of its own stamps, not of the whole run)
        s0 = max(int(np.searchsorted(table[:, 0], kf[0], side="right")) - 1, 0)
        s1 = int(np.searchsorted(table[:, 0], kf[-1], side="left"))
        table = table[s0 : max(s1, s0 + 1)]
        times, v, w = table[:, 0], table[:, 1], table[:, 2]
        inside = times[(times > kf[0]) & (times < kf[-1])]
        bp = np.union1d(kf, inside)
        dt = np.diff(bp)
        sample = np.searchsorted(times, bp[:-1], side="right") - 1
        active = sample >= 0
        seg_v = np.where(active, v[np.maximum(sample, 0)], 0.0)
        seg_w = np.where(active, w[np.maximum(sample, 0)], 0.0)
        ds = seg_v * dt
        dth = seg_w * dt
        half = 0.5 * dth
        chord = ds * np.sinc(half / np.pi)
        x0, y0, th0 = self.state
        theta = np.cumsum(np.concatenate([[th0], dth]))
        mid = theta[:-1] + half
        x = np.cumsum(np.concatenate([[x0], chord * np.cos(mid)]))
        y = np.cumsum(np.concatenate([[y0], chord * np.sin(mid)]))
        kf_idx = np.searchsorted(bp, kf)
        poses = np.stack([x[kf_idx], y[kf_idx], _wrap(theta[kf_idx])], axis=1)
        deltas = relative_poses(np.stack([x[kf_idx], y[kf_idx], theta[kf_idx]], axis=1))
        self.stamp = float(kf[-1])
        self.state = (x[-1], y[-1], theta[-1])
        poses = np.concatenate([first, poses[1:]])
        if not self.covariances:
            return poses, deltas, np.zeros((0, 3, 3))
        return poses, deltas, step_covariances(x, y, theta, mid, dt, kf_idx, self.noise)


class GrowingArray:
    """A growable float array (amortized appends) with its filled part as a view."""

    def __init__(self, width: int = 0):
        self.shape = (width,) if width else ()
        self.data = np.zeros((64, *self.shape))
        self.n = 0

    def append(self, rows: np.ndarray) -> None:
        rows = np.asarray(rows, dtype=float).reshape(-1, *self.shape)
        while self.n + len(rows) > len(self.data):
            self.data = np.concatenate([self.data, np.zeros_like(self.data)])
        self.data[self.n : self.n + len(rows)] = rows
        self.n += len(rows)

    @property
    def view(self) -> np.ndarray:
        return self.data[: self.n]
