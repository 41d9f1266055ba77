"""Seed 000 (000_05137a0a9c449be3.txt) Sec. V: the belief vector over the P3P solutions.

Sec. V-A: every valid solution starts with belief 1/K (eq. 11 normalizer); each solution is
traced to the nearest neighbour of the previous frame (Sec. VI-B: same track if closer than
0.05 m and optical axes ("normal vectors") with dot product >= 0.85), giving the observed motion
om_t; a solution without such a neighbour gets om = inf (likelihood 0). Eq. (12): belief_i <-
belief_i * f(om_i, a_i), then normalize; commit when max belief > 0.95 (Sec. V-C MCA line 7),
relocate when the committed belief falls back to the threshold (Sec. V-A, last sentences).

Likelihoods (Sec. V-B):
- Def. 1 ("inner_product"): the normalized inner product a.om / (|a||om|), floored at `floor`
  (a negative cosine would zero the belief for good).
- Def. 1 read as a similarity in [0, 1] ("inner_product_shifted"): (1 + a.om / (|a||om|)) / 2.
- Def. 2 ("distance_angle"): d = |a - om| + lambda arccos(a.om / (|a||om|)), eq. (13). Eq. (13)
  is a distance (0 for identical vectors); the belief update needs a similarity, so the
  likelihood is exp(-d) (d in metres + lambda * radians; "relatively large lambda").
- Def. 2 read as an inverse distance ("distance_angle_inverse"): 1 / (1 + d).
The seed names neither mapping; benchmarks.seed_baselines sweeps them.
`action_frame` "world" reads a_t as a world-frame motion reading, the same vector for every
solution (the odometry handed in is then a world displacement), instead of rotating it by each
solution's rotation.

a_i is the action of solution i: the odometry translation (camera frame of the previous pose)
rotated into the world by that solution's rotation -- the superscript (i) of a_{t-1}^{(i)} in
eq. (12). The 0.05 m gate is per regular update interval (0.1 s); the first update spans 0.3 s
(Sec. VI-B), so the gate scales with the elapsed time. When every belief is zero (all tracks
lost) the vector restarts uniformly on the current solutions, as at t = 0.
"""

from __future__ import annotations


from typing import Literal
import gtsam
import numpy as np

from graphloc.config_schema import config_dataclass, setting
from graphloc.candidates import CandidateSet
from graphloc.seams import Decision, Odometry, check_frame

ACTION_FRAMES = ("solution", "world")
LIKELIHOODS = (
    "inner_product",
    "inner_product_shifted",
    "distance_angle",
    "distance_angle_inverse",
)


@config_dataclass
class BeliefVectorConfig:
    likelihood: Literal[LIKELIHOODS] = "inner_product"
    lam: float = setting(5.0, ge=0.0)
    floor: float = 1e-3
    gate_distance: float = setting(0.05, gt=0.0)
    gate_interval: float = setting(0.1, gt=0.0)
    min_normal_dot: float = 0.85
    threshold: float = setting(0.95, gt=0.0, lt=1.0)
    action_frame: Literal[ACTION_FRAMES] = "solution"


def likelihood(a: np.ndarray, om: np.ndarray, config: BeliefVectorConfig) -> np.ndarray:
    """f(om, a) of Sec. V-B for rows a, om (N,3); rows with non-finite om give 0."""
    na, no = np.linalg.norm(a, axis=1), np.linalg.norm(om, axis=1)
    ok = np.isfinite(no)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.clip(
            np.einsum("ij,ij->i", a, np.where(ok[:, None], om, 0.0)) / (na * no), -1.0, 1.0
        )
    cos = np.where(np.isfinite(cos), cos, 0.0)
    if config.likelihood == "inner_product":
        f = np.maximum(cos, config.floor)
    elif config.likelihood == "inner_product_shifted":
        f = 0.5 * (1.0 + cos)
    else:
        d = np.linalg.norm(a - np.where(ok[:, None], om, 0.0), axis=1) + config.lam * np.arccos(cos)
        f = np.exp(-d) if config.likelihood == "distance_angle" else 1.0 / (1.0 + d)
    return np.where(ok, f, 0.0)


class BeliefVector:
    """update(candidates, odometry) -> Decision, the same interface as HypothesisTracker."""

    def __init__(self, config: BeliefVectorConfig = BeliefVectorConfig()):
        self.config = config
        self._R = np.zeros((0, 3, 3))  # tracked solutions of the previous frame
        self._t = np.zeros((0, 3))
        self._belief = np.zeros(0)
        self._assigned = np.zeros(
            0, dtype=int
        )  # candidate index (this frame) of each tracked solution
        self._committed: int | None = None  # index into the tracked solutions
        self._last_time: float | None = None

    def update(self, candidates: CandidateSet, odometry: Odometry | None = None) -> Decision:
        cfg = self.config
        check_frame(
            candidates, odometry, self._last_time is None, self._last_time, "BeliefVector.update"
        )
        dt = None if self._last_time is None else candidates.time - self._last_time
        self._last_time = candidates.time
        relocalized = False
        if len(self._belief) and len(candidates) and odometry is not None:
            # nearest-neighbour trace of every tracked solution into this frame
            d = np.linalg.norm(self._t[:, None, :] - candidates.t[None, :, :], axis=2)
            nn = np.argmin(d, axis=1)
            rows = np.arange(len(nn))
            normal_dot = np.einsum("ki,ki->k", self._R[:, :, 2], candidates.R[nn][:, :, 2])
            gate = cfg.gate_distance * max(dt / cfg.gate_interval, 1.0)
            traced = (d[rows, nn] < gate) & (normal_dot >= cfg.min_normal_dot)
            om = np.where(traced[:, None], candidates.t[nn] - self._t, np.inf)
            step = odometry.relative.translation()
            a = (
                self._R @ step
                if cfg.action_frame == "solution"
                else np.broadcast_to(step, self._t.shape)
            )
            belief = self._belief * likelihood(a, om, cfg)
            keep = traced & (belief > 0)
            if keep.any():
                if self._committed is not None and not keep[self._committed]:
                    self._committed, relocalized = None, True
                if self._committed is not None:
                    self._committed = int(np.cumsum(keep)[self._committed] - 1)
                self._R, self._t = candidates.R[nn[keep]], candidates.t[nn[keep]]
                self._belief = belief[keep] / belief[keep].sum()
                self._assigned = nn[keep]
            else:
                self._belief = np.zeros(0)
        elif len(self._belief) and not len(candidates):
            self._belief = np.zeros(0)
        if not len(self._belief):  # t = 0, or every track lost: uniform restart (Sec. V-A)
            relocalized = relocalized or self._committed is not None
            self._committed = None
            self._R, self._t = candidates.R.copy(), candidates.t.copy()
            self._belief = np.full(len(candidates), 1.0 / max(len(candidates), 1))
            self._assigned = np.arange(len(candidates))
        if self._committed is not None and self._belief[self._committed] <= cfg.threshold:
            self._committed, relocalized = None, True
        if self._committed is None and len(self._belief) and self._belief.max() > cfg.threshold:
            self._committed = int(np.argmax(self._belief))
        probs = np.zeros(len(candidates))
        np.add.at(probs, self._assigned, self._belief)
        if not len(self._belief):
            return Decision(probs, -1, False, None, relocalized)
        best = self._committed if self._committed is not None else int(np.argmax(self._belief))
        pose = gtsam.Pose3(gtsam.Rot3(self._R[best]), self._t[best])
        committed = int(self._assigned[self._committed]) if self._committed is not None else -1
        return Decision(probs, committed, self._committed is not None, pose, relocalized)
