"""The estimation engine: one factor list, two ways to solve it.

`Session` has one front door -- `add(factors, initial_values, time=...)`, `estimate()`,
`marginal_covariance(key)` -- and two modes over the SAME factor list:

- "batch":  gtsam.LevenbergMarquardtOptimizer over the whole graph (re-run lazily when
  `estimate()` is asked after new factors arrived);
- "online": gtsam.ISAM2, one incremental `update` per `add` (wall-clock latency recorded).

State is serializable: `save(path)` pickles the config and the list of `add` steps (GTSAM 4.3
factors and Values pickle; Python-side factor providers such as `MaxMixture` pickle as the
built-in factors and weights that rebuild them); `Session.load(path)` rebuilds the graph and, in online
mode, replays the steps into a fresh iSAM2 with the same parameters, which reproduces the
estimates exactly (iSAM2 is deterministic given the same update sequence).

Example (GTSAM-example style: explicit keys, one graph, one optimizer):

    from graphloc.keys import pose_key
    s = Session(SessionConfig(mode="online"))
    g = gtsam.NonlinearFactorGraph(); g.add(gtsam.PriorFactorPose2(pose_key(0, 0), gtsam.Pose2(), noise))
    v = gtsam.Values(); v.insert(pose_key(0, 0), gtsam.Pose2())
    s.add(g, v, time=0.0)
    s.estimate().atPose2(pose_key(0, 0))
"""

from __future__ import annotations

import pickle
import time as _time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Iterable

import gtsam
import numpy as np

MODES = ("batch", "online")
_SAVE_FORMAT = "graphloc-session"
_SAVE_VERSION = 2  # 2: steps hold the added items (factors and factor providers)


@dataclass(frozen=True)
class SessionConfig:
    """mode: "batch" (Levenberg-Marquardt) or "online" (iSAM2).

    LM: lm_max_iterations, lm_relative_error_tol, lm_absolute_error_tol.
    iSAM2: relinearize_threshold (on the delta of any variable), relinearize_skip (relinearize
    every N updates), extra_updates (additional `update()` calls after each add, to converge
    further), factorization ("CHOLESKY" or "QR"), wildfire_threshold (back-substitution stops
    where the solution changes less than this), partial_relinearization_check (only check the
    variables of re-eliminated cliques for relinearization), isam2_optimizer: "gauss_newton"
    (iSAM2's default step) or "dogleg" (Powell's dog leg with an adaptive trust region: a
    step that would raise the error is shortened, which stops the period-2 oscillation an
    undamped step can fall into on stiff graphs).
    """

    mode: str = "batch"
    lm_max_iterations: int = 100
    lm_relative_error_tol: float = 1e-6
    lm_absolute_error_tol: float = 1e-6
    relinearize_threshold: float = 0.05
    relinearize_skip: int = 1
    extra_updates: int = 0
    factorization: str = "CHOLESKY"
    wildfire_threshold: float = 0.001
    partial_relinearization_check: bool = False
    isam2_optimizer: str = "gauss_newton"

    def __post_init__(self):
        if self.mode not in MODES:
            raise ValueError(f"SessionConfig.mode must be one of {MODES}, got {self.mode!r}")
        if self.isam2_optimizer not in ("gauss_newton", "dogleg"):
            raise ValueError(f"SessionConfig.isam2_optimizer must be gauss_newton or dogleg, got "
                             f"{self.isam2_optimizer!r}")
        if self.factorization not in ("CHOLESKY", "QR"):
            raise ValueError(f"SessionConfig.factorization must be CHOLESKY or QR, got {self.factorization!r}")
        if self.lm_max_iterations < 1 or self.relinearize_skip < 1 or self.extra_updates < 0:
            raise ValueError("SessionConfig: lm_max_iterations and relinearize_skip must be >= 1, extra_updates >= 0")
        if not (self.wildfire_threshold >= 0 and np.isfinite(self.wildfire_threshold)):
            raise ValueError(f"SessionConfig.wildfire_threshold must be finite >= 0, got {self.wildfire_threshold}")
        if not (self.relinearize_threshold >= 0 and np.isfinite(self.relinearize_threshold)):
            raise ValueError(f"SessionConfig.relinearize_threshold must be finite >= 0, got {self.relinearize_threshold}")


@dataclass(frozen=True)
class Step:
    """One `add` call: its time stamp, how many factors and new variables, wall-clock latency [s]
    (in online mode the iSAM2 update; in batch mode only the bookkeeping)."""

    time: float
    n_factors: int
    n_new_values: int
    latency_s: float


@dataclass
class _Record:
    """What `save` keeps of one step so that `load` can replay it."""

    time: float
    items: list  # what `add` was given: gtsam factors and factor providers (e.g. MaxMixture)
    values: gtsam.Values
    latency_s: float = field(default=0.0)


def _as_items(factors) -> list:
    """The factors of one `add` call as a list. A *factor provider* -- an object with a `factor`
    attribute holding a gtsam factor, such as `graphloc.factors.mixture.MaxMixture` -- is kept as
    itself so that `save` can pickle what rebuilds it (GTSAM cannot serialize a Python
    CustomFactor)."""
    if isinstance(factors, gtsam.NonlinearFactorGraph):
        return [factors.at(i) for i in range(factors.size()) if factors.exists(i)]
    return list(factors)


def _as_graph(items: list) -> gtsam.NonlinearFactorGraph:
    graph = gtsam.NonlinearFactorGraph()
    for item in items:
        graph.add(getattr(item, "factor", item))
    return graph


class Session:
    """Batch (LM) or online (iSAM2) smoothing over one growing factor graph."""

    def __init__(self, config: SessionConfig = SessionConfig()):
        self.config = config
        self.graph = gtsam.NonlinearFactorGraph()  # every factor ever added, in order
        self.initial = gtsam.Values()  # initial guess of every variable ever added
        self.steps: list[Step] = []
        self._records: list[_Record] = []
        self._last_time = -np.inf
        self._batch_estimate: gtsam.Values | None = None
        self._batch_marginals: gtsam.Marginals | None = None
        self._batch_iterations = 0
        self._isam = self._make_isam() if config.mode == "online" else None

    # ---- construction --------------------------------------------------------------------
    def _make_isam(self) -> gtsam.ISAM2:
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(self.config.relinearize_threshold)
        params.relinearizeSkip = self.config.relinearize_skip
        params.setFactorization(self.config.factorization)
        params.enablePartialRelinearizationCheck = self.config.partial_relinearization_check
        if self.config.isam2_optimizer == "dogleg":
            step = gtsam.ISAM2DoglegParams()
        else:
            step = gtsam.ISAM2GaussNewtonParams()
        step.setWildfireThreshold(self.config.wildfire_threshold)
        params.setOptimizationParams(step)
        return gtsam.ISAM2(params)

    # ---- the front door ------------------------------------------------------------------
    def add(self, factors: gtsam.NonlinearFactorGraph | Iterable, initial_values: gtsam.Values,
            time: float | None = None) -> Step:
        """Append `factors` (a NonlinearFactorGraph or iterable of factors) and the initial guess of
        the variables they introduce. `time` must not go backwards (None: same as the previous step).
        Every key a factor touches must be known already or be in `initial_values`; keys in
        `initial_values` must be new. A system GTSAM cannot solve (e.g. an unconstrained variable)
        raises ValueError."""
        items = _as_items(factors)
        graph = _as_graph(items)
        if time is None:  # same time as the previous step (0 for the first)
            t = self._last_time if self.steps else 0.0
        else:
            t = float(time)
        if not np.isfinite(t):
            raise ValueError(f"Session.add: time {time!r} is not finite")
        if t < self._last_time:
            raise ValueError(f"Session.add: time goes backwards ({t} < previous {self._last_time})")
        new_keys = set(initial_values.keys())
        clash = [gtsam.DefaultKeyFormatter(k) for k in new_keys if self.initial.exists(k)]
        if clash:
            raise ValueError(f"Session.add: initial values for keys already in the session: {clash[:5]}")
        missing = sorted({k for k in graph.keyVector() if not self.initial.exists(k) and k not in new_keys})
        if missing:
            names = [gtsam.DefaultKeyFormatter(k) for k in missing[:5]]
            raise ValueError(f"Session.add: factors reference keys without a value: {names}")

        start = _time.perf_counter()
        if self._isam is not None:
            try:
                self._isam.update(graph, initial_values)
                for _ in range(self.config.extra_updates):
                    self._isam.update()
            except RuntimeError as exc:
                raise ValueError(f"Session.add at time {t}: iSAM2 update failed ({exc}); the online session "
                                 f"is unusable after this, reload a saved state") from None
        latency = _time.perf_counter() - start

        self.graph.push_back(graph)
        self.initial.insert(initial_values)
        self._batch_estimate = self._batch_marginals = None
        self._last_time = t
        step = Step(time=t, n_factors=int(graph.size()), n_new_values=len(new_keys), latency_s=latency)
        self.steps.append(step)
        self._records.append(_Record(t, items, initial_values, latency))
        return step

    def estimate(self, keys: Iterable[int] | None = None) -> gtsam.Values:
        """Current estimate of all variables (or only `keys`). Batch: LM from the initial guess over
        the whole graph (cached until the next `add`). Online: iSAM2's current estimate."""
        if keys is not None:
            keys = list(keys)
            self._check_known(keys, "estimate")
        if self._isam is not None:
            if keys is None:
                return self._isam.calculateEstimate()
            return self._isam.calculateEstimate(keys)
        if self._batch_estimate is None:
            self._batch_estimate = self._optimize_batch()
        if keys is None:
            return self._batch_estimate
        return _subset(self._batch_estimate, keys)

    def marginal_covariance(self, key: int) -> np.ndarray:
        """Marginal covariance of one variable at the current estimate (tangent-space, GTSAM order)."""
        self._check_known([key], "marginal_covariance")
        if self._isam is not None:
            return np.asarray(self._isam.marginalCovariance(key))
        if self._batch_marginals is None:  # one factorization per estimate, not per query
            self._batch_marginals = gtsam.Marginals(self.graph, self.estimate())
        return np.asarray(self._batch_marginals.marginalCovariance(key))

    def _check_known(self, keys: list, what: str) -> None:
        unknown = [gtsam.DefaultKeyFormatter(k) for k in keys if not self.initial.exists(k)]
        if unknown:
            raise ValueError(f"Session.{what}: no variable {unknown[:5]} in this session")

    # ---- diagnostics ---------------------------------------------------------------------
    @property
    def batch_iterations(self) -> int:
        return self._batch_iterations

    def latencies(self) -> np.ndarray:
        """(n_steps,) wall-clock seconds of each `add` (the iSAM2 update in online mode)."""
        return np.array([s.latency_s for s in self.steps], dtype=float)

    def error(self, values: gtsam.Values | None = None) -> float:
        """Total graph error (0.5 * sum of whitened, robustified squared residuals)."""
        return float(self.graph.error(self.estimate() if values is None else values))

    def _optimize_batch(self) -> gtsam.Values:
        if self.graph.size() == 0:
            return gtsam.Values()
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(self.config.lm_max_iterations)
        params.setRelativeErrorTol(self.config.lm_relative_error_tol)
        params.setAbsoluteErrorTol(self.config.lm_absolute_error_tol)
        optimizer = gtsam.LevenbergMarquardtOptimizer(self.graph, self.initial, params)
        try:
            result = optimizer.optimize()
        except RuntimeError as exc:
            raise ValueError(f"Session: batch optimization failed ({exc})") from None
        self._batch_iterations = int(optimizer.iterations())
        return result

    # ---- persistence ---------------------------------------------------------------------
    def save(self, path: str | Path) -> None:
        """Pickle config + every step (factors, initial values, time) to `path`. A bare
        gtsam.CustomFactor cannot be serialized: add the provider that builds it (e.g. a
        `MaxMixture` object rather than its `.factor`) if the session is to be saved."""
        for i, record in enumerate(self._records):
            bare = [type(it).__name__ for it in record.items if isinstance(it, gtsam.CustomFactor)]
            if bare:
                raise ValueError(f"Session.save: step {i} (time {record.time}) holds a bare gtsam.CustomFactor, which "
                                 f"GTSAM cannot serialize; add its provider object (e.g. MaxMixture) instead")
        payload = {
            "format": _SAVE_FORMAT,
            "version": _SAVE_VERSION,
            "config": asdict(self.config),
            "steps": [(r.time, r.items, r.values, r.latency_s) for r in self._records],
        }
        with open(path, "wb") as fh:
            pickle.dump(payload, fh, protocol=pickle.HIGHEST_PROTOCOL)

    @classmethod
    def load(cls, path: str | Path) -> "Session":
        """Rebuild a saved session; online sessions replay every step into a fresh iSAM2."""
        with open(path, "rb") as fh:
            payload = pickle.load(fh)
        if not isinstance(payload, dict) or payload.get("format") != _SAVE_FORMAT:
            raise ValueError(f"{path}: not a saved graphloc session")
        if payload.get("version") != _SAVE_VERSION:
            raise ValueError(f"{path}: session format version {payload.get('version')} unsupported")
        session = cls(SessionConfig(**payload["config"]))
        for t, factors, values, _latency in payload["steps"]:
            session.add(factors, values, time=t)
        return session


def _subset(values: gtsam.Values, keys: Iterable[int]) -> gtsam.Values:
    """The entries of `values` at `keys` (unknown keys raise ValueError)."""
    wanted = set(keys)
    missing = [gtsam.DefaultKeyFormatter(k) for k in wanted if not values.exists(k)]
    if missing:
        raise ValueError(f"no estimate for keys {missing[:5]}")
    out = gtsam.Values(values)
    for k in values.keys():
        if k not in wanted:
            out.erase(k)
    return out
