"""The estimation engine: one factor list, two ways to solve it.

`Session` has one front door -- `add(factors, initial_values, time=...)`, `estimate()`,
`marginal_covariance(key)` -- and two modes over the SAME factor list:

- "batch":  gtsam.LevenbergMarquardtOptimizer over the whole graph (re-run lazily when
  `estimate()` is asked after new factors arrived);
- "online": gtsam.ISAM2, one incremental `update` per `add` (wall-clock latency recorded).

State is saved as data, never as code: `save(path)` writes the config and the list of `add`
steps as JSON (format "graphloc-session", version 3; the codec is `graphloc.session_codec`,
the file format `graphloc.datafile`): every factor as its GTSAM type name, keys, measurement
and noise model (the built-in factors graphloc uses), every Values entry as numbers, and
Python-side factor providers such as `MaxMixture` as the components and weights that rebuild
them (`save_state` / `from_state`). Loading parses JSON and
calls GTSAM constructors on checked numbers only: no pickle, and no Boost archive either (GTSAM's
`deserialize` crashes the interpreter on a corrupted archive). The file is written atomically
(temporary file, fsync, rename) with a SHA-256 of its body, so a failure midway leaves the
previous file intact and a truncated or altered file is a ValueError naming the file.
`Session.load(path)` rebuilds the graph and, in online mode, replays the steps into a fresh
iSAM2 with the same parameters, which reproduces the estimates exactly (iSAM2 is deterministic
given the same update sequence; a 3-D bearing (Unit3) is re-normalized on load, which can move
it by 1 ulp).

Example (GTSAM-example style: explicit keys, one graph, one optimizer):

    from graphloc.keys import pose_key
    s = Session(SessionConfig(mode="online"))
    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.PriorFactorPose2(pose_key(0, 0), gtsam.Pose2(), noise))
    v = gtsam.Values(); v.insert(pose_key(0, 0), gtsam.Pose2())
    s.add(g, v, time=0.0)
    s.estimate().atPose2(pose_key(0, 0))
"""

from __future__ import annotations

import collections
import math
import time as _time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Iterable

import gtsam
import numpy as np
from tqdm import tqdm

from graphloc.datafile import BadData, read_data_file, write_data_file
from graphloc.session_codec import decode_step, encode_item, encode_values, key_name

__all__ = ["MODES", "Session", "SessionConfig", "Step", "read_data_file", "write_data_file"]

MODES = ("batch", "online")
_SAVE_FORMAT = "graphloc-session"
_SAVE_VERSION = 3  # 3: JSON + SHA-256 (2 was a pickle, no longer read: unpickling runs code)


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
    lag [s]: online only; 0 keeps every variable (full smoothing); > 0 is a fixed lag: iSAM2
    that marginalizes, with `ISAM2::marginalizeLeaves`, every variable added more than `lag`
    seconds (of the add times) before the newest (`_update_fixed_lag`: a constrained ordering
    by add time keeps those variables leaves of the Bayes tree, so no re-elimination is
    needed): the tree and the per-step cost stay bounded; a marginalized variable keeps its
    last estimate, and a factor on one is refused (`Session.add` raises ValueError;
    `Session.marginalized` tells first). A variable's stamp is its add time and is not renewed
    when later factors touch it, so long-lived variables (a static robot's pose, a SLAM
    landmark) leave the window too. marginalize_every [s] (0: `lag`): stamps are add times
    rounded down to a multiple of it; old variables leave in one batch every
    `marginalize_every` seconds (the window spans `lag` to `lag + marginalize_every`), and
    every update orders one group per live stamp.
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
    lag: float = 0.0
    marginalize_every: float = 0.0

    def __post_init__(self):
        if not (np.isfinite(self.lag) and self.lag >= 0):
            raise ValueError(f"SessionConfig.lag must be finite >= 0, got {self.lag}")
        if not (np.isfinite(self.marginalize_every) and self.marginalize_every >= 0):
            raise ValueError(
                f"SessionConfig.marginalize_every must be finite >= 0, got {self.marginalize_every}"
            )
        if self.mode not in MODES:
            raise ValueError(f"SessionConfig.mode must be one of {MODES}, got {self.mode!r}")
        if self.isam2_optimizer not in ("gauss_newton", "dogleg"):
            raise ValueError(
                f"SessionConfig.isam2_optimizer must be gauss_newton or dogleg, got "
                f"{self.isam2_optimizer!r}"
            )
        if self.factorization not in ("CHOLESKY", "QR"):
            raise ValueError(
                f"SessionConfig.factorization must be CHOLESKY or QR, got {self.factorization!r}"
            )
        counts = (self.lm_max_iterations, self.relinearize_skip, self.extra_updates)
        if max(counts) >= 2**31:
            raise ValueError(
                f"SessionConfig: lm_max_iterations, relinearize_skip and "
                f"extra_updates must be < 2^31, got {counts}"
            )
        if self.lm_max_iterations < 1 or self.relinearize_skip < 1 or self.extra_updates < 0:
            raise ValueError(
                "SessionConfig: lm_max_iterations and relinearize_skip must be >= 1, "
                "extra_updates >= 0"
            )
        if not (self.wildfire_threshold >= 0 and np.isfinite(self.wildfire_threshold)):
            raise ValueError(
                "SessionConfig.wildfire_threshold must be finite >= 0, "
                f"got {self.wildfire_threshold}"
            )
        if not (self.relinearize_threshold >= 0 and np.isfinite(self.relinearize_threshold)):
            raise ValueError(
                "SessionConfig.relinearize_threshold must be finite >= 0, "
                f"got {self.relinearize_threshold}"
            )


@dataclass(frozen=True)
class Step:
    """One `add` call: its time stamp, how many factors and new variables, wall-clock latency [s]
    (in online mode the iSAM2 update; in batch mode only the bookkeeping)."""

    time: float
    n_factors: int
    n_new_values: int
    latency_s: float
    cpu_s: float = 0.0  # CPU time of this thread over the same span


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

    def __init__(self, config: SessionConfig = SessionConfig(), progress: bool = False, stop=None):
        self.config = config
        self.progress = progress  # a progress bar (iteration, error) during a batch solve
        self.stop = stop  # stop(): checked between LM iterations; True ends the solve there
        self.stopped = False  # the last batch solve was ended by `stop`
        self.graph = gtsam.NonlinearFactorGraph()  # every factor ever added, in order
        self.initial = gtsam.Values()  # initial guess of every variable ever added
        self.steps: list[Step] = []
        self._records: list[_Record] = []
        self._last_time = -np.inf
        self._batch_estimate: gtsam.Values | None = None
        self._batch_marginals: gtsam.Marginals | None = None
        self._batch_iterations = 0
        self._isam = self._make_isam() if config.mode == "online" else None
        # fixed lag: the add time of each live variable; marginalized variables' last estimates
        self._touched: dict[int, float] = {}
        self._newest = -np.inf
        self._frozen = gtsam.Values()
        self._groups = gtsam.KeyGroupMap()  # live key -> the rank of its stamp
        self._ranks: dict[float, int] = {}  # live stamp -> its rank (ordering group)
        self._by_stamp: dict[float, list] = {}  # live stamp -> its keys, oldest stamp first
        # the most recent keys, always re-eliminated: more than the groups there can be
        stamps = 2 + (
            math.ceil(config.lag / (config.marginalize_every or config.lag)) if config.lag else 0
        )
        n = stamps + 2
        self._in_newest = 0  # live keys with the newest stamp
        self._recent: collections.deque = collections.deque(maxlen=n)

    # ---- construction --------------------------------------------------------------------
    def _make_isam(self):
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

    @property
    def fixed_lag(self) -> bool:
        return self._isam is not None and self.config.lag > 0

    def marginalized(self, key: int) -> bool:
        """Whether `key` was marginalized by the fixed-lag smoother (its value is frozen)."""
        return self._frozen.exists(key)

    def _frozen_or_live(self, key: int):
        if self._frozen.exists(key):
            return _value(self._frozen, key)
        for get in (
            self._isam.calculateEstimatePose3,
            self._isam.calculateEstimatePose2,
            self._isam.calculateEstimatePoint3,
            self._isam.calculateEstimateVector,
        ):
            try:
                return get(key)
            except RuntimeError:
                continue
        raise RuntimeError(
            f"no estimate of type Pose3, Pose2, Point3 or vector for {key_name(key)}"
        )

    def _update_fixed_lag(
        self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, t: float
    ) -> None:
        """One fixed-lag update (iSAM2 with `ISAM2::marginalizeLeaves`). New keys are stamped
        with t rounded down to a multiple of `marginalize_every`. Every update passes iSAM2 a
        constrained ordering with one group per live stamp, oldest first, so that every
        (re-)elimination eliminates older stamps first: a key's subtree then holds only keys of
        its own stamp or older ones, and the keys stamped more than `lag` before the newest
        stamp are leaves, marginalized by `marginalizeLeaves` alone, without re-eliminating the
        window (GTSAM's IncrementalFixedLagSmoother re-orders and re-eliminates the path from
        the marginalized cliques to the root whenever it marginalizes). They keep their
        estimate from before the marginalization. CCOLAMD takes group numbers below the number
        of variables it orders, so the groups are the ranks of the live stamps and the most
        recent keys (at least one more than there are stamps) are always re-eliminated too
        (they are at the top of the tree, re-eliminated by most updates anyway)."""
        quantum = self.config.marginalize_every or self.config.lag
        now = math.floor(t / quantum) * quantum  # add times never go back
        old = []
        if now > self._newest:  # a new stamp: the next rank; only it can make keys old
            self._newest = now
            self._ranks[now] = len(self._ranks)
            self._in_newest = 0
            self._by_stamp[now] = []
            limit = now - self.config.lag - 1e-9 * quantum
            while next(iter(self._by_stamp)) < limit:  # stamps in time order
                old += self._by_stamp.pop(next(iter(self._by_stamp)))
        rank = self._ranks[now]
        extra = _key_list(self._recent) if self._recent else None
        for k in values.keys():
            self._touched[k] = now
            self._by_stamp[now].append(k)
            self._groups.insert2(k, rank)
            self._recent.append(k)
        self._in_newest += values.size()
        # this update only: the keys of the new factors that have the newest stamp go last
        # (iSAM2's own default constrains the new factors' keys last), one group above the
        # newest stamp's (used only when that stamp has other keys)
        top = [k for k in set(graph.keyVector()) if self._touched[k] == now]
        bump = 0 < len(top) < self._in_newest
        for k in top if bump else ():
            self._groups.insert2(k, rank + 1)
        self._isam.update(graph, values, [], self._groups, None, extra)
        for k in top if bump else ():
            self._groups.insert2(k, rank)
        for _ in range(self.config.extra_updates):
            extra = _key_list(self._recent)
            empty = gtsam.NonlinearFactorGraph()
            self._isam.update(empty, gtsam.Values(), [], self._groups, None, extra)
        if not old:
            return
        # the marginalized keys keep their estimate; the live stamps are renumbered from 0
        self._frozen.insert(self._isam.calculateEstimate(old))
        self._isam.marginalizeLeaves(_key_list(old))
        for k in old:
            del self._touched[k]
        self._ranks = {stamp: r for r, stamp in enumerate(self._by_stamp)}
        self._groups = gtsam.KeyGroupMap()
        for stamp, keys in self._by_stamp.items():
            for k in keys:
                self._groups.insert2(k, self._ranks[stamp])
        self._recent = collections.deque(
            (k for k in self._recent if k in self._touched), maxlen=self._recent.maxlen
        )

    # ---- the front door ------------------------------------------------------------------
    def add(
        self,
        factors: gtsam.NonlinearFactorGraph | Iterable,
        initial_values: gtsam.Values,
        time: float | None = None,
    ) -> Step:
        """Append `factors` (a NonlinearFactorGraph or iterable of factors) and the initial guess of
        the variables they introduce. `time` must not go backwards (None: same as the previous
        step). Every key a factor touches must be known already or be in `initial_values`; keys in
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
        clash = [key_name(k) for k in new_keys if self.initial.exists(k)]
        if clash:
            raise ValueError(
                f"Session.add: initial values for keys already in the session: {clash[:5]}"
            )
        missing = sorted(
            {k for k in graph.keyVector() if not self.initial.exists(k) and k not in new_keys}
        )
        if missing:
            names = [key_name(k) for k in missing[:5]]
            raise ValueError(f"Session.add: factors reference keys without a value: {names}")

        gone = [key_name(k) for k in graph.keyVector() if self._frozen.exists(k)]
        if gone:
            raise ValueError(
                f"Session.add: factors reference marginalized keys (older than the lag): {gone[:5]}"
            )
        start, cpu_start = _time.perf_counter(), _time.thread_time()
        if self.fixed_lag:
            try:
                self._update_fixed_lag(graph, initial_values, t)
            except RuntimeError as exc:
                raise ValueError(
                    f"Session.add at time {t}: fixed-lag update failed ({_first_line(exc)})"
                ) from None
        elif self._isam is not None:
            try:
                self._isam.update(graph, initial_values)
                for _ in range(self.config.extra_updates):
                    self._isam.update()
            except RuntimeError as exc:
                raise ValueError(
                    f"Session.add at time {t}: iSAM2 update failed ({exc}); the online session "
                    f"is unusable after this, reload a saved state"
                ) from None
        latency, cpu = _time.perf_counter() - start, _time.thread_time() - cpu_start

        self.graph.push_back(graph)
        self.initial.insert(initial_values)
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
        self._records.append(_Record(t, items, initial_values, latency))
        return step

    def estimate(self, keys: Iterable[int] | None = None) -> gtsam.Values:
        """Current estimate of all variables (or only `keys`). Batch: LM from the initial guess over
        the whole graph (cached until the next `add`). Online: iSAM2's current estimate."""
        if keys is not None:
            keys = list(keys)
            self._check_known(keys, "estimate")
        if self.fixed_lag:
            try:
                if keys is None:
                    out = gtsam.Values(self._frozen)
                    out.insert(self._isam.calculateEstimate())
                    return out
                out = gtsam.Values()
                for k in keys:  # one variable at a time: no estimate of the whole window
                    out.insert(k, self._frozen_or_live(k))
                return out
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
        unknown = [key_name(k) for k in keys if not self.initial.exists(k)]
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
        return len(self._touched) if self.fixed_lag else int(self.initial.size())

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

    # ---- persistence ---------------------------------------------------------------------
    def save(self, path: str | Path) -> None:
        """Write config + every step (factors, providers, initial values, time) to `path` as
        versioned JSON, atomically (see the module docstring). A bare gtsam.CustomFactor cannot
        be saved: add the provider that builds it (e.g. a `MaxMixture` object rather than its
        `.factor`). ValueError names the step and factor that cannot be written."""
        steps = []
        for i, record in enumerate(self._records):
            where = f"Session.save: step {i} (time {record.time})"
            bare = [type(it).__name__ for it in record.items if isinstance(it, gtsam.CustomFactor)]
            if bare:
                raise ValueError(
                    f"{where} holds a bare gtsam.CustomFactor, which cannot be "
                    f"saved; add its provider object (e.g. MaxMixture) instead"
                )
            items = [encode_item(item, f"{where}, item {j}") for j, item in enumerate(record.items)]
            steps.append(
                {
                    "time": record.time,
                    "latency_s": record.latency_s,
                    "items": items,
                    "values": encode_values(record.values, where),
                }
            )
        write_data_file(
            path, _SAVE_FORMAT, _SAVE_VERSION, {"config": asdict(self.config), "steps": steps}
        )

    @classmethod
    def load(cls, path: str | Path) -> "Session":
        """Rebuild a saved session; online sessions replay every step into a fresh iSAM2. Any
        problem with the file (unreadable, not a session, truncated, altered, an unknown factor
        type, a step the session rejects) is a ValueError naming the file."""
        payload = read_data_file(path, _SAVE_FORMAT, _SAVE_VERSION, "session")
        try:
            session = cls(_config_from(payload.get("config")))
            steps = payload.get("steps")
            if not isinstance(steps, list):
                raise BadData("'steps' must be a list")
            for i, step in enumerate(steps):
                t, items, values = decode_step(step, f"step {i}")
                try:
                    session.add(items, values, time=t)
                except ValueError as exc:
                    raise BadData(f"step {i}: {exc}") from None
        except BadData as exc:
            raise ValueError(f"{path}: {exc}") from None
        return session


def _config_from(raw) -> SessionConfig:
    """SessionConfig from its saved dict: every field present, of the default's type."""
    if not isinstance(raw, dict):
        raise BadData("'config' must be an object")
    known = {f.name: type(f.default) for f in fields(SessionConfig)}
    unknown = sorted(set(raw) - set(known))
    if unknown:
        raise BadData(f"config: unknown fields {unknown}")
    for name, value in raw.items():
        kind = known[name]
        ok = isinstance(value, kind) and not (kind is not bool and isinstance(value, bool))
        if kind is float:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not ok:
            raise BadData(f"config.{name}: expected {kind.__name__}, got {value!r}")
    try:
        return SessionConfig(**raw)
    except ValueError as exc:
        raise BadData(f"config: {exc}") from None


def _key_list(keys: Iterable[int]) -> gtsam.KeyList:
    out = gtsam.KeyList()
    for k in keys:
        out.push_back(k)
    return out


def _value(values: gtsam.Values, key: int):
    """The entry of `values` at `key` as its own type (Pose3, Pose2, Point3 / vector)."""
    for get in (values.atPose3, values.atPose2, values.atPoint3, values.atVector):
        try:
            return get(key)
        except RuntimeError:
            continue
    raise ValueError(f"no estimate for key {key_name(key)}")


def _first_line(exc: Exception) -> str:
    """The first non-empty line of a GTSAM exception's message (they run to a page)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return lines[0] if lines else type(exc).__name__


def _subset(values: gtsam.Values, keys: Iterable[int]) -> gtsam.Values:
    """The entries of `values` at `keys` (unknown keys raise ValueError)."""
    wanted = set(keys)
    missing = [key_name(k) for k in wanted if not values.exists(k)]
    if missing:
        raise ValueError(f"no estimate for keys {missing[:5]}")
    out = gtsam.Values(values)
    for k in values.keys():
        if k not in wanted:
            out.erase(k)
    return out
