"""The estimation engine: one factor list solved in batch (Levenberg-Marquardt, re-run lazily when
`estimate()` follows new factors) or online (iSAM2, one update per `add`)."""

from __future__ import annotations

import re
import time as _time
from dataclasses import dataclass
from typing import Iterable

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.exitcodes import SolverFailure
from graphloc.fixed_lag import FixedLagWindow
from graphloc.session_config import MODES, SessionConfig
from graphloc.session_config import check_thresholded, relinearize_threshold
from graphloc.keys import key_name

__all__ = ["MODES", "Session", "SessionConfig", "Step"]


@dataclass(frozen=True, slots=True)
class Step:
    """One `add` call: its time stamp, how many factors and new variables, wall-clock latency [s]
    (in online mode the iSAM2 update; in batch mode only the bookkeeping)."""

    time: float
    n_factors: int
    n_new_values: int
    latency_s: float
    cpu_s: float = 0.0  # CPU time of this thread over the same span


def _as_graph(factors) -> gtsam.NonlinearFactorGraph:
    """The factors of one `add` call as a graph (a factor provider such as `MaxMixture` adds its
    `factor`)."""
    if isinstance(factors, gtsam.NonlinearFactorGraph):
        factors = [factors.at(i) for i in range(factors.size()) if factors.exists(i)]
    graph = gtsam.NonlinearFactorGraph()
    for item in factors:
        graph.add(getattr(item, "factor", item))
    return graph


class Session:
    """Batch (LM) or online (iSAM2) smoothing over one growing factor graph."""

    def __init__(self, config: SessionConfig = SessionConfig(), progress: bool = False, stop=None):
        self.config = config
        self.progress = progress  # a progress bar (iteration, error) during a batch solve
        self.stop = stop  # stop(): checked between LM iterations; True ends the solve there
        self.stopped = False  # the last batch solve was ended by `stop`
        self.graph = gtsam.NonlinearFactorGraph()  # every factor ever added, in order
        # batch: the initial guess of every variable ever added (what LM starts from); online
        # sessions hand the guesses to iSAM2 and keep none
        self.initial = gtsam.Values() if config.mode == "batch" else None
        self.steps: list[Step] = []
        self._keys: set = set()  # the keys of every variable ever added
        self._last_time = -np.inf
        self._batch_estimate: gtsam.Values | None = None
        self._batch_marginals: gtsam.Marginals | None = None
        self._batch_iterations = 0
        self._isam = self._make_isam() if config.mode == "online" else None
        lagged = self._isam is not None and config.lag > 0  # online, a fixed lag
        self._window = FixedLagWindow(self._isam, config) if lagged else None

    # ---- construction --------------------------------------------------------------------
    def _make_isam(self):
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(relinearize_threshold(self.config))
        params.relinearizeSkip = self.config.relinearize_skip
        params.setFactorization(self.config.factorization)
        params.enablePartialRelinearizationCheck = self.config.partial_relinearization_check
        params.findUnusedFactorSlots = self.config.lag > 0  # marginalized factors' slots
        if self.config.isam2_optimizer == "dogleg":
            step = gtsam.ISAM2DoglegParams()
        else:
            step = gtsam.ISAM2GaussNewtonParams()
        step.setWildfireThreshold(self.config.wildfire_threshold)
        params.setOptimizationParams(step)
        return gtsam.ISAM2(params)

    @property
    def fixed_lag(self) -> bool:
        return self._window is not None

    def marginalized(self, key: int) -> bool:
        """Whether `key` was marginalized by the fixed-lag smoother (its value is frozen)."""
        return key in self.marginalized_keys

    @property
    def marginalized_keys(self) -> frozenset | set:
        """Every key `marginalized` is True for, as a set (do not modify)."""
        return self._window.frozen_keys if self._window is not None else frozenset()

    # ---- the front door ------------------------------------------------------------------
    def add(
        self,
        factors: gtsam.NonlinearFactorGraph | Iterable,
        initial_values: gtsam.Values,
        time: float | None = None,
    ) -> Step:
        """Append `factors` and the initial guess of the variables they introduce at `time`
        (None: the previous step's; never backwards). ValueError for new keys already known,
        factors on unknown or marginalized keys, or a system GTSAM cannot solve."""
        graph = _as_graph(factors)
        if time is None:  # same time as the previous step (0 for the first)
            t = self._last_time if self.steps else 0.0
        else:
            t = float(time)
        if not np.isfinite(t):
            raise ValueError(f"Session.add: time {time!r} is not finite")
        if t < self._last_time:
            raise ValueError(f"Session.add: time goes backwards ({t} < previous {self._last_time})")
        new_keys = set(initial_values.keys())
        clash = [key_name(k) for k in new_keys & self._keys]
        if clash:
            raise ValueError(
                f"Session.add: initial values for keys already in the session: {clash[:5]}"
            )
        check_thresholded(self.config, new_keys)
        old_keys = set(graph.keyVector()) - new_keys
        missing = sorted(old_keys - self._keys)
        if missing:
            names = [key_name(k) for k in missing[:5]]
            raise ValueError(f"Session.add: factors reference keys without a value: {names}")

        gone = [key_name(k) for k in sorted(old_keys & self.marginalized_keys)]
        if gone:
            raise ValueError(
                f"Session.add: factors reference marginalized keys (older than the lag): {gone[:5]}"
            )
        start, cpu_start = _time.perf_counter(), _time.thread_time()
        if self.fixed_lag:
            try:
                self._window.update(graph, initial_values, t)
            except RuntimeError as exc:
                raise SolverFailure(
                    f"Session.add at time {t}: fixed-lag update failed ({_first_line(exc)})"
                ) from None
        elif self._isam is not None:
            try:
                self._isam.update(graph, initial_values)
                for _ in range(self.config.extra_updates):
                    self._isam.update()
            except RuntimeError as exc:
                raise SolverFailure(
                    f"Session.add at time {t}: iSAM2 update failed ({_first_line(exc)}); the "
                    f"online session is unusable after this, reload a saved state"
                ) from None
        latency, cpu = _time.perf_counter() - start, _time.thread_time() - cpu_start

        self.graph.push_back(graph)
        if self.initial is not None:
            self.initial.insert(initial_values)
        self._keys |= new_keys
        self._batch_estimate = self._batch_marginals = None
        self._last_time = t
        step = Step(
            time=t,
            n_factors=int(graph.size()),
            n_new_values=len(new_keys),
            latency_s=latency,
            cpu_s=cpu,
        )
        self.steps.append(step)
        return step

    def iterate(self) -> float:
        """Online: one more iSAM2 iteration over what was added, every variable whose delta
        exceeds the relinearization threshold relinearized whatever `relinearize_skip` says
        (a fixed-lag session: one more update). Returns its wall time [s]."""
        if self._isam is None:
            raise ValueError("Session.iterate: only an online session iterates")
        start = _time.perf_counter()
        try:
            if self.fixed_lag:
                self._window.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), self._last_time)
            else:
                self._isam.update(
                    gtsam.NonlinearFactorGraph(), gtsam.Values(), force_relinearize=True
                )
        except RuntimeError as exc:
            raise SolverFailure(
                f"Session.iterate: iSAM2 update failed ({_first_line(exc)})"
            ) from None
        return _time.perf_counter() - start

    def estimate(self, keys: Iterable[int] | None = None) -> gtsam.Values:
        """Current estimate of all variables (or only `keys`). Batch: LM from the initial guess over
        the whole graph (cached until the next `add`). Online: iSAM2's current estimate."""
        if keys is not None:
            keys = list(keys)
            self._check_known(keys, "estimate")
        if self.fixed_lag:
            try:
                return self._window.estimate(keys)
            except RuntimeError as exc:
                raise ValueError(
                    f"Session.estimate: the fixed-lag smoother cannot solve the "
                    f"graph ({_first_line(exc)})"
                ) from None
        if self._isam is not None:
            try:
                return (
                    self._isam.calculateEstimate()
                    if keys is None
                    else self._isam.calculateEstimate(keys)
                )
            except RuntimeError as exc:  # e.g. an indeterminate system after a bad update
                raise ValueError(
                    f"Session.estimate: iSAM2 cannot solve the graph ({_first_line(exc)})"
                ) from None
        if self._batch_estimate is None:
            self._batch_estimate = self._optimize_batch()
        if keys is None:
            return self._batch_estimate
        return _subset(self._batch_estimate, keys)

    def marginal_covariance(self, key: int) -> np.ndarray:
        """Marginal covariance of one variable at the current estimate (tangent-space, GTSAM
        order)."""
        self._check_known([key], "marginal_covariance")
        try:
            if self.marginalized(key):
                raise ValueError(
                    f"Session.marginal_covariance({key_name(key)}): the "
                    f"variable was marginalized (older than the lag)"
                )
            if self._isam is not None:
                return np.asarray(self._isam.marginalCovariance(key))
            if self._batch_marginals is None:  # one factorization per estimate, not per query
                self._batch_marginals = gtsam.Marginals(self.graph, self.estimate())
            return np.asarray(self._batch_marginals.marginalCovariance(key))
        except RuntimeError as exc:
            raise ValueError(
                f"Session.marginal_covariance({key_name(key)}): "
                f"GTSAM cannot compute it ({_first_line(exc)})"
            ) from None

    def _check_known(self, keys: list, what: str) -> None:
        unknown = [key_name(k) for k in keys if k not in self._keys]
        if unknown:
            raise ValueError(f"Session.{what}: no variable {unknown[:5]} in this session")

    # ---- diagnostics ---------------------------------------------------------------------
    @property
    def batch_iterations(self) -> int:
        return self._batch_iterations

    def latencies(self) -> np.ndarray:
        """(n_steps,) wall-clock seconds of each `add` (the iSAM2 update in online mode)."""
        return np.array([s.latency_s for s in self.steps], dtype=float)

    def live_variables(self) -> int:
        """Variables the solver holds: all of them, or (fixed lag) those inside the lag."""
        return len(self._window.touched) if self.fixed_lag else len(self._keys)

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
        # GTSAM's own optimize() loop (NonlinearOptimizer::defaultOptimize), iteration by
        # iteration so that long solves show their progress
        bar = tqdm(
            total=params.getMaxIterations(),
            desc="Levenberg-Marquardt",
            unit="it",
            disable=not self.progress,
        )
        try:
            error = optimizer.error()
            while (
                error > params.getErrorTol() and optimizer.iterations() < params.getMaxIterations()
            ):
                if self.stop is not None and self.stop():
                    self.stopped = True
                    break
                optimizer.iterate()
                new_error = optimizer.error()
                bar.update(1)
                bar.set_postfix(error=f"{new_error:.6g}")
                done = gtsam.checkConvergence(params, error, new_error) or not np.isfinite(
                    new_error
                )
                error = new_error
                if done:
                    break
        except RuntimeError as exc:
            raise ValueError(f"Session: batch optimization failed ({exc})") from None
        finally:
            bar.close()
        self._batch_iterations = int(optimizer.iterations())
        return optimizer.values()


def _first_line(exc: Exception) -> str:
    """The first non-empty line of a GTSAM exception's message (they run to a page), with the
    variable it names (an IndeterminateLinearSystemException's "(Symbol: x0)")."""
    text = str(exc)
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    first = lines[0] if lines else type(exc).__name__
    symbol = re.search(r"\(Symbol: (\w+)\)", text)
    return f"{first} {symbol.group(1)}" if symbol and symbol.group(1) not in first else first


def _subset(values: gtsam.Values, keys: Iterable[int]) -> gtsam.Values:
    """The entries of `values` at `keys` (unknown keys raise ValueError)."""
    wanted = sorted(set(keys))
    missing = [key_name(k) for k in wanted if not values.exists(k)]
    if missing:
        raise ValueError(f"no estimate for keys {missing[:5]}")
    return values.extract(wanted)
