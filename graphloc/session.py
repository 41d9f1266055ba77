"""The estimation engine: one factor list, two ways to solve it.

`Session` has one front door -- `add(factors, initial_values, time=...)`, `estimate()`,
`marginal_covariance(key)` -- and two modes over the SAME factor list:

- "batch":  gtsam.LevenbergMarquardtOptimizer over the whole graph (re-run lazily when
  `estimate()` is asked after new factors arrived);
- "online": gtsam.ISAM2, one incremental `update` per `add` (wall-clock latency recorded).

State is saved as data, never as code: `save(path)` writes the config and the list of `add`
steps as JSON (format "graphloc-session", version 3): every factor as its GTSAM type name,
keys, measurement and noise model (`_FACTOR_TYPES`, the built-in factors graphloc uses), every
Values entry as numbers, and Python-side factor providers such as `MaxMixture` as the
components and weights that rebuild them (`save_state` / `from_state`). Loading parses JSON and
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

import hashlib
import json
import math
import os
import tempfile
import time as _time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Iterable

import gtsam
import numpy as np
from tqdm import tqdm

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
    lag [s]: online only; 0 keeps every variable (full smoothing); > 0 runs GTSAM's
    IncrementalFixedLagSmoother (iSAM2 that marginalizes, with `ISAM2::marginalizeLeaves`, every
    variable added more than `lag` seconds (of the add times) before the newest): the Bayes
    tree and the per-step cost stay bounded; a marginalized variable keeps its last estimate,
    and a factor on one is refused (`Session.add` raises ValueError; `Session.marginalized`
    tells first). A variable's stamp is its add time and is not renewed when later factors
    touch it (with re-stamped keys GTSAM 4.3's smoother failed in marginalizeLeaves on the
    MRCLAM team graph, "remove variables ... that are not unused"; a plain pose chain does not
    show it), so long-lived variables (a static robot's pose, a SLAM landmark) leave the
    window too. lag_batches: stamp variables with
    their add time rounded down to a multiple of `lag`, so that old variables leave in one
    batch per `lag` seconds (the window then spans `lag` to 2 `lag`): the smoother re-eliminates
    the path from the marginalized cliques to the root whenever it marginalizes, once per lag
    instead of at every step.
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
    lag_batches: bool = True

    def __post_init__(self):
        if not (np.isfinite(self.lag) and self.lag >= 0):
            raise ValueError(f"SessionConfig.lag must be finite >= 0, got {self.lag}")
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
        if self.config.lag > 0:
            return gtsam.IncrementalFixedLagSmoother(self.config.lag, params)
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
            f"no estimate of type Pose3, Pose2, Point3 or vector for {_key_name(key)}"
        )

    def _update_fixed_lag(
        self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, t: float
    ) -> None:
        """One fixed-lag update: the new keys get time t; the keys the smoother marginalizes
        keep their estimate from before this update."""
        quantum = self.config.lag if self.config.lag_batches else 0.0
        now = math.floor(t / quantum) * quantum if quantum else t  # add times never go back
        stamps = {int(k): now for k in values.keys()}
        self._touched.update(stamps)
        # IncrementalFixedLagSmoother marginalizes the keys stamped before (newest - lag); new
        # keys get the newest stamp, so only a newer stamp can make keys old
        old = []
        if now > self._newest:
            old = [k for k, s in self._touched.items() if s < now - self.config.lag + 1e-9]
            self._newest = now
        before = self._isam.calculateEstimate() if old else None
        self._isam.update(graph, values, stamps)
        for _ in range(self.config.extra_updates):
            self._isam.update()
        if not old:
            return
        alive = self._isam.timestamps()
        for k in old:
            if k not in alive:
                del self._touched[k]
                self._frozen.insert(k, _value(before, k))

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
        clash = [_key_name(k) for k in new_keys if self.initial.exists(k)]
        if clash:
            raise ValueError(
                f"Session.add: initial values for keys already in the session: {clash[:5]}"
            )
        missing = sorted(
            {k for k in graph.keyVector() if not self.initial.exists(k) and k not in new_keys}
        )
        if missing:
            names = [_key_name(k) for k in missing[:5]]
            raise ValueError(f"Session.add: factors reference keys without a value: {names}")

        gone = [_key_name(k) for k in graph.keyVector() if self._frozen.exists(k)]
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
                    f"Session.marginal_covariance({_key_name(key)}): the "
                    f"variable was marginalized (older than the lag)"
                )
            if self._isam is not None:
                return np.asarray(self._isam.marginalCovariance(key))
            if self._batch_marginals is None:  # one factorization per estimate, not per query
                self._batch_marginals = gtsam.Marginals(self.graph, self.estimate())
            return np.asarray(self._batch_marginals.marginalCovariance(key))
        except RuntimeError as exc:
            raise ValueError(
                f"Session.marginal_covariance({_key_name(key)}): "
                f"GTSAM cannot compute it ({_first_line(exc)})"
            ) from None

    def _check_known(self, keys: list, what: str) -> None:
        unknown = [_key_name(k) for k in keys if not self.initial.exists(k)]
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
            items = [
                _encode_item(item, f"{where}, item {j}") for j, item in enumerate(record.items)
            ]
            steps.append(
                {
                    "time": record.time,
                    "latency_s": record.latency_s,
                    "items": items,
                    "values": _encode_values(record.values, where),
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
                raise _Bad("'steps' must be a list")
            for i, step in enumerate(steps):
                t, items, values = _decode_step(step, f"step {i}")
                try:
                    session.add(items, values, time=t)
                except ValueError as exc:
                    raise _Bad(f"step {i}: {exc}") from None
        except _Bad as exc:
            raise ValueError(f"{path}: {exc}") from None
        return session


class _Bad(Exception):
    """A malformed session file (turned into ValueError naming the file by `Session.load`)."""


# ---- versioned data files (also used by graphloc.hypotheses) ----------------------------------
def write_data_file(
    path: str | Path, fmt: str, version: int, payload: dict, allow_nan: bool = False
) -> None:
    """Write `payload` as a graphloc data file: one JSON header line (format, version, body size
    and SHA-256) and a JSON body, atomically. allow_nan: write inf/NaN as JSON constants
    (Infinity, NaN) instead of raising ValueError."""
    body = json.dumps(payload, allow_nan=allow_nan, separators=(",", ":")).encode()
    header = {
        "format": fmt,
        "version": version,
        "body_bytes": len(body),
        "body_sha256": hashlib.sha256(body).hexdigest(),
    }
    write_atomically(Path(path), json.dumps(header).encode() + b"\n" + body)


def read_data_file(
    path: str | Path, fmt: str, version: int, what: str, allow_nan: bool = False
) -> dict:
    """The JSON body of a file `write_data_file` wrote, after checking format, version, size
    and SHA-256. ValueError naming the file (and saying what is wrong) on anything else: an
    unreadable file, a pickle, another format or version, a truncated or altered body."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the {what} file ({exc.strerror})") from None
    try:
        return _parse_data_file(data, fmt, version, what, allow_nan)
    except _Bad as exc:
        raise ValueError(f"{path}: {exc}") from None


def write_atomically(path: Path, data: bytes) -> None:
    """Write `data` to a temporary file beside `path`, fsync it, rename it over `path` and fsync
    the directory: `path` holds either the old or the new content, never a partial one. An
    OSError (missing directory, disk full, `path` a directory) names `path`."""
    directory = path.parent
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    except OSError as exc:
        raise type(exc)(exc.errno, f"{path}: cannot write ({exc.strerror})") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise type(exc)(exc.errno, f"{path}: cannot write ({exc.strerror})") from None
        raise
    try:
        dir_fd = os.open(directory, os.O_RDONLY)
    except OSError:  # a directory that cannot be opened (some platforms): the rename is done
        return
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


def _parse_data_file(data: bytes, fmt: str, version: int, what: str, allow_nan: bool) -> dict:
    if data[:1] == b"\x80":
        raise _Bad(
            f"not a saved graphloc {what}: a Python pickle (an older graphloc format or "
            f"foreign), which is not loaded because unpickling can run code; re-save it"
        )
    head, sep, body = data.partition(b"\n")
    try:
        header = json.loads(head.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        header = None
    if not sep or not isinstance(header, dict) or header.get("format") != fmt:
        raise _Bad(f"not a saved graphloc {what} (no {fmt} header line)")
    if header.get("version") != version:
        raise _Bad(
            f"{what} format version {header.get('version')!r} unsupported (this graphloc "
            f"reads version {version})"
        )
    if header.get("body_bytes") != len(body):
        raise _Bad(
            f"truncated or altered: body has {len(body)} bytes, header says "
            f"{header.get('body_bytes')!r}"
        )
    if header.get("body_sha256") != hashlib.sha256(body).hexdigest():
        raise _Bad("altered or corrupted: the SHA-256 of the body does not match the header")
    try:
        constant = None if allow_nan else _reject_constant
        payload = json.loads(body.decode("utf-8"), parse_constant=constant)
    except (UnicodeDecodeError, ValueError) as exc:
        raise _Bad(f"body is not valid JSON ({exc})") from None
    if not isinstance(payload, dict):
        raise _Bad("body must be a JSON object")
    return payload


def _reject_constant(name: str):
    raise ValueError(f"{name} is not a finite number")


def _config_from(raw) -> SessionConfig:
    """SessionConfig from its saved dict: every field present, of the default's type."""
    if not isinstance(raw, dict):
        raise _Bad("'config' must be an object")
    known = {f.name: type(f.default) for f in fields(SessionConfig)}
    unknown = sorted(set(raw) - set(known))
    if unknown:
        raise _Bad(f"config: unknown fields {unknown}")
    for name, value in raw.items():
        kind = known[name]
        ok = isinstance(value, kind) and not (kind is not bool and isinstance(value, bool))
        if kind is float:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not ok:
            raise _Bad(f"config.{name}: expected {kind.__name__}, got {value!r}")
    try:
        return SessionConfig(**raw)
    except ValueError as exc:
        raise _Bad(f"config: {exc}") from None


# ---- the codec: built-in factors, noise models and values as JSON numbers ----------------------
# measurement kinds: how a factor's measurement is written and rebuilt
_FACTOR_TYPES = {
    **{
        f"PriorFactor{t}": ("prior", k, 1)
        for t, k in (
            ("Pose2", "pose2"),
            ("Pose3", "pose3"),
            ("Rot2", "rot2"),
            ("Rot3", "rot3"),
            ("Point2", "vector"),
            ("Point3", "vector"),
            ("Unit3", "unit3"),
            ("Double", "double"),
        )
    },
    **{
        f"BetweenFactor{t}": ("measured", k, 2)
        for t, k in (
            ("Pose2", "pose2"),
            ("Pose3", "pose3"),
            ("Rot2", "rot2"),
            ("Rot3", "rot3"),
            ("Point2", "vector"),
            ("Point3", "vector"),
            ("Double", "double"),
        )
    },
    **{
        f"RangeFactor{t}": ("measured", "double", 2)
        for t in ("2", "2D", "3", "3D", "Pose2", "Pose3")
    },
    "RangeFactorWithTransformPose3": ("measured", "double", 2),  # + body_T_sensor
    "BearingFactor2D": ("measured", "rot2", 2),
    "BearingFactorPose2": ("measured", "rot2", 2),
    "BearingFactor3D": ("measured", "unit3", 2),
    "BearingRangeFactor2D": ("measured", "bearing_range_2d", 2),
    "BearingRangeFactorPose2": ("measured", "bearing_range_2d", 2),
    "BearingRangeFactor3D": ("measured", "bearing_range_3d", 2),
    "BearingRangeFactorPose3": ("measured", "bearing_range_3d", 2),
    "AttitudeFactorPose3": ("nRef", "unit3", 1),  # + bMeasured
    "GenericProjectionFactorCal3_S2": ("measured", "vector", 2),  # + calibration, cheirality flags
}
_KERNELS = ("Huber", "Cauchy", "Tukey", "GemanMcClure", "DCS", "Welsch", "Fair")
_PROVIDERS = ("max_mixture",)


def _encode_measurement(kind: str, m) -> list:
    if kind == "pose2":
        return [m.x(), m.y(), m.rotation().c(), m.rotation().s()]
    if kind == "rot2":
        return [m.c(), m.s()]
    if kind in ("pose3", "rot3"):
        return np.asarray(m.matrix(), dtype=float).ravel().tolist()
    if kind == "unit3":
        return np.asarray(m.point3(), dtype=float).tolist()
    if kind == "double":
        return [float(m)]
    if kind == "bearing_range_2d":
        return [m.bearing().c(), m.bearing().s(), float(m.range())]
    if kind == "bearing_range_3d":
        return np.asarray(m.bearing().point3(), dtype=float).tolist() + [float(m.range())]
    return np.asarray(m, dtype=float).ravel().tolist()  # vector


_MEASUREMENT_SIZES = {
    "pose2": 4,
    "rot2": 2,
    "pose3": 16,
    "rot3": 9,
    "unit3": 3,
    "double": 1,
    "bearing_range_2d": 3,
    "bearing_range_3d": 4,
}


def _decode_measurement(kind: str, v: list, where: str):
    want = _MEASUREMENT_SIZES.get(kind)
    if (want is not None and len(v) != want) or (want is None and not v):
        raise _Bad(f"{where}: a {kind} measurement needs {want or '>= 1'} numbers, got {len(v)}")
    if kind == "pose2":
        return gtsam.Pose2(_rot2(v[2], v[3], where), np.array(v[:2]))
    if kind == "rot2":
        return _rot2(v[0], v[1], where)
    if kind == "pose3":
        T = np.array(v).reshape(4, 4)
        return gtsam.Pose3(_rot3(T[:3, :3], where), T[:3, 3])
    if kind == "rot3":
        return _rot3(np.array(v).reshape(3, 3), where)
    if kind == "unit3":
        return _unit3(v, where)
    if kind == "double":
        return v[0]
    if kind == "bearing_range_2d":
        return _rot2(v[0], v[1], where), _range(v[2], where)
    if kind == "bearing_range_3d":
        return _unit3(v[:3], where), _range(v[3], where)
    return np.array(v)


def _rot2(c: float, s: float, where: str) -> gtsam.Rot2:
    if abs(math.hypot(c, s) - 1.0) > 1e-9:
        raise _Bad(f"{where}: rotation (cos, sin) = ({c}, {s}) is not a unit vector")
    return gtsam.Rot2.fromCosSin(c, s)


def _rot3(R: np.ndarray, where: str) -> gtsam.Rot3:
    with np.errstate(all="ignore"):  # entries of 1e300 overflow: not a rotation either way
        ok = np.abs(R @ R.T - np.eye(3)).max() < 1e-9 and np.linalg.det(R) > 0
    if not ok:
        raise _Bad(f"{where}: 3x3 matrix is not a rotation")
    return gtsam.Rot3(R)


def _unit3(v, where: str) -> gtsam.Unit3:
    with np.errstate(all="ignore"):
        norm = float(np.linalg.norm(v))
    if not abs(norm - 1.0) <= 1e-9:
        raise _Bad(f"{where}: direction {v} is not a unit vector")
    return gtsam.Unit3(np.array(v, dtype=float))


def _range(r: float, where: str) -> float:
    if not r >= 0:
        raise _Bad(f"{where}: range {r} is negative")
    return r


def _kernel_parameters(robust, where: str) -> tuple[str, int, float]:
    """(name, reweight scheme, parameter) of an mEstimator. GTSAM's Python API has no getter for
    the parameter, so it is read from the estimator's own archive of this in-memory object and
    checked by rebuilding the estimator and comparing the two archives."""
    name = type(robust).__name__
    if name not in _KERNELS:
        raise ValueError(
            f"{where}: robust kernel {name} cannot be saved (saved kernels: {_KERNELS})"
        )
    archive = robust.serialize()
    tokens = archive.split()
    try:
        scheme, param = int(tokens[8]), float(tokens[9])
        rebuilt = _make_kernel(name, scheme, param).serialize()
    except (IndexError, ValueError, RuntimeError):
        rebuilt = None
    if rebuilt != archive:
        raise ValueError(
            f"{where}: cannot read the parameter of robust kernel {name} from its archive"
        )
    return name, scheme, param


def _make_kernel(name: str, scheme: int, param: float):
    schemes = gtsam.noiseModel.mEstimator.Base.ReweightScheme
    scheme = schemes.Block if scheme else schemes.Scalar
    return getattr(gtsam.noiseModel.mEstimator, name).Create(param, scheme)


def _encode_noise(model, where: str) -> dict:
    nm = gtsam.noiseModel
    if isinstance(model, nm.Robust):
        name, scheme, param = _kernel_parameters(model.robust(), where)
        return {
            "robust": name,
            "scheme": scheme,
            "k": param,
            "base": _encode_noise(model.noise(), where),
        }
    if isinstance(model, nm.Constrained):
        raise ValueError(f"{where}: a Constrained noise model cannot be saved")
    if isinstance(model, nm.Unit):
        return {"unit": model.dim()}
    if isinstance(model, nm.Isotropic):
        return {"isotropic": model.dim(), "sigma": float(model.sigma())}
    if isinstance(model, nm.Diagonal):
        return {"sigmas": np.asarray(model.sigmas(), dtype=float).tolist()}
    if isinstance(model, nm.Gaussian):
        return {"sqrt_information": np.asarray(model.R(), dtype=float).tolist()}
    raise ValueError(f"{where}: noise model {type(model).__name__} cannot be saved")


def _decode_noise(raw, where: str, depth: int = 0):
    nm = gtsam.noiseModel
    if not isinstance(raw, dict) or (depth and "robust" in raw):
        raise _Bad(f"{where}: noise model must be an object (robust over a Gaussian model)")
    if "robust" in raw:
        name, scheme, k = raw.get("robust"), raw.get("scheme"), raw.get("k")
        if name not in _KERNELS or scheme not in (0, 1) or not (_is_number(k) and k > 0):
            raise _Bad(
                f"{where}: robust kernel must be one of {_KERNELS} with scheme 0/1 and "
                f"k > 0, got {name!r}, {scheme!r}, {k!r}"
            )
        base = _decode_noise(raw.get("base"), where, 1)
        return nm.Robust.Create(_make_kernel(name, scheme, float(k)), base)
    if "unit" in raw:
        return nm.Unit.Create(_dim(raw["unit"], where))
    if "isotropic" in raw:
        sigma = raw.get("sigma")
        if not (_is_number(sigma) and sigma > 0):
            raise _Bad(f"{where}: isotropic sigma must be > 0, got {sigma!r}")
        return nm.Isotropic.Sigma(_dim(raw["isotropic"], where), float(sigma))
    if "sigmas" in raw:
        sigmas = _numbers(raw["sigmas"], f"{where}: sigmas")
        if not (1 <= len(sigmas) <= 64 and min(sigmas) > 0):
            raise _Bad(f"{where}: need 1 to 64 sigmas > 0, got {sigmas}")
        return nm.Diagonal.Sigmas(np.array(sigmas), False)
    if "sqrt_information" in raw:
        rows = raw["sqrt_information"]
        if not isinstance(rows, list) or not 1 <= len(rows) <= 64:
            raise _Bad(f"{where}: sqrt_information must be a list of 1 to 64 rows")
        R = np.array([_numbers(r, f"{where}: sqrt_information") for r in rows], dtype=object)
        if R.ndim != 2 or R.shape[0] != R.shape[1]:
            raise _Bad(f"{where}: sqrt_information must be square")
        R = R.astype(float)
        if np.abs(np.tril(R, -1)).max(initial=0.0) != 0 or not (np.diag(R) > 0).all():
            raise _Bad(
                f"{where}: sqrt_information must be upper triangular with a positive diagonal"
            )
        return nm.Gaussian.SqrtInformation(R, False)
    raise _Bad(f"{where}: unknown noise model {sorted(raw)}")


def _encode_factor(f, where: str) -> dict:
    name = type(f).__name__
    spec = _FACTOR_TYPES.get(name)
    if spec is None:
        raise ValueError(
            f"{where}: factor type {name} cannot be saved (saved types: built-in "
            f"{', '.join(sorted(_FACTOR_TYPES))}, and factor providers {_PROVIDERS})"
        )
    getter, kind, n_keys = spec
    out = {
        "type": name,
        "keys": [int(k) for k in f.keys()],
        "measured": _encode_measurement(kind, getattr(f, getter)()),
        "noise": _encode_noise(f.noiseModel(), where),
    }
    if name == "AttitudeFactorPose3":
        out["b_measured"] = _encode_measurement("unit3", f.bMeasured())
    if name == "GenericProjectionFactorCal3_S2":
        out["calibration"] = np.asarray(f.calibration().vector(), dtype=float).tolist()
        out["cheirality"] = [bool(f.throwCheirality()), bool(f.verboseCheirality())]
        rebuilt = _make_factor(name, out["keys"], f.measured(), f.noiseModel(), out).serialize()
        if rebuilt != f.serialize():  # e.g. a body_P_sensor, which has no getter
            raise ValueError(f"{where}: {name} with a body_P_sensor cannot be saved")
    if name == "RangeFactorWithTransformPose3":  # body_T_sensor has no getter: from the archive
        archive = f.serialize()
        tokens = archive.split()
        try:
            body = np.array([float(x) for x in tokens[-14:-5] + tokens[-3:]])
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = body[:9].reshape(3, 3), body[9:]
            rebuilt = _make_factor(name, out["keys"], f.measured(), f.noiseModel(), T).serialize()
        except (ValueError, RuntimeError):
            rebuilt = None
        if rebuilt != archive:
            raise ValueError(f"{where}: cannot read body_T_sensor of {name} from its archive")
        out["body_T_sensor"] = T.ravel().tolist()
    return out


def _make_factor(name: str, keys: list, measured, noise, extra=None):
    cls = getattr(gtsam, name)
    if name == "GenericProjectionFactorCal3_S2":
        return cls(
            np.asarray(measured),
            noise,
            *keys,
            gtsam.Cal3_S2(*extra["calibration"]),
            *extra["cheirality"],
        )
    if name == "RangeFactorWithTransformPose3":
        T = np.asarray(extra)
        return cls(*keys, measured, noise, gtsam.Pose3(gtsam.Rot3(T[:3, :3]), T[:3, 3]))
    if isinstance(measured, tuple):  # bearing, range
        return cls(*keys, *measured, noise)
    return cls(*keys, measured, noise)


def _decode_factor(raw, where: str):
    if not isinstance(raw, dict):
        raise _Bad(f"{where}: a factor must be an object")
    name = raw.get("type")
    spec = _FACTOR_TYPES.get(name) if isinstance(name, str) else None
    if spec is None or not hasattr(gtsam, name):
        raise _Bad(f"{where}: unknown factor type {name!r}")
    _, kind, n_keys = spec
    keys = raw.get("keys")
    if not (isinstance(keys, list) and len(keys) == n_keys and all(_is_key(k) for k in keys)):
        raise _Bad(f"{where}: {name} needs {n_keys} keys (integers in [0, 2^64)), got {keys!r}")
    measured = _decode_measurement(kind, _numbers(raw.get("measured"), f"{where}: measured"), where)
    noise = _decode_noise(raw.get("noise"), where)
    try:
        if name == "AttitudeFactorPose3":
            b = _unit3(_numbers(raw.get("b_measured"), f"{where}: b_measured"), where)
            factor = gtsam.AttitudeFactorPose3(keys[0], measured, noise, b)
        elif name == "GenericProjectionFactorCal3_S2":
            if len(measured) != 2:
                raise _Bad(f"{where}: {name} needs a 2-vector pixel, got {len(measured)} numbers")
            cal = _numbers(raw.get("calibration"), f"{where}: calibration")
            flags = raw.get("cheirality")
            if len(cal) != 5 or not (cal[0] > 0 and cal[1] > 0):
                raise _Bad(
                    f"{where}: calibration must be fx, fy, s, u0, v0 with fx, fy > 0, got {cal}"
                )
            if not (
                isinstance(flags, list)
                and len(flags) == 2
                and all(isinstance(b, bool) for b in flags)
            ):
                raise _Bad(f"{where}: cheirality must be two booleans, got {flags!r}")
            extra = {"calibration": cal, "cheirality": flags}
            factor = _make_factor(name, keys, measured, noise, extra)
        elif name == "RangeFactorWithTransformPose3":
            T = np.array(_numbers(raw.get("body_T_sensor"), f"{where}: body_T_sensor"))
            if T.size != 16:
                raise _Bad(f"{where}: body_T_sensor needs 16 numbers, got {T.size}")
            T = T.reshape(4, 4)
            _rot3(T[:3, :3], f"{where}: body_T_sensor")
            factor = _make_factor(name, keys, measured, noise, T)
        else:
            factor = _make_factor(name, keys, measured, noise)
    except (RuntimeError, TypeError) as exc:  # e.g. a noise dimension the factor does not have
        raise _Bad(f"{where}: GTSAM rejected the {name} ({exc})") from None
    want = {
        "pose2": 3,
        "pose3": 6,
        "rot2": 1,
        "rot3": 3,
        "unit3": 2,
        "double": 1,
        "bearing_range_2d": 2,
        "bearing_range_3d": 3,
    }.get(kind, len(raw["measured"]))
    if noise.dim() != want:  # a mismatch GTSAM would not notice could corrupt memory
        raise _Bad(
            f"{where}: {name} has an error of dimension {want}, its noise model {noise.dim()}"
        )
    return factor


def _encode_item(item, where: str) -> dict:
    """One added item: a built-in factor, or a factor provider (an object with `save_state`)."""
    if hasattr(item, "save_state"):
        state = item.save_state()
        return {
            "provider": state["kind"],
            "weights": [float(w) for w in state["weights"]],
            "components": [
                [_encode_factor(f, f"{where}, component {c}") for f in group]
                for c, group in enumerate(state["components"])
            ],
        }
    if hasattr(item, "factor") and not isinstance(item, gtsam.NonlinearFactor):
        raise ValueError(
            f"{where}: factor provider {type(item).__name__} has no save_state(), cannot be saved"
        )
    return _encode_factor(item, where)


def _decode_item(raw, where: str):
    if isinstance(raw, dict) and "provider" in raw:
        if raw["provider"] != "max_mixture":
            raise _Bad(
                f"{where}: unknown factor provider {raw['provider']!r} (known: {_PROVIDERS})"
            )
        from graphloc.factors.mixture import MaxMixture

        groups = raw.get("components")
        if not isinstance(groups, list) or not all(isinstance(g, list) for g in groups):
            raise _Bad(f"{where}: max_mixture components must be a list of lists of factors")
        components = [
            [_decode_factor(f, f"{where}, component {c}") for f in g] for c, g in enumerate(groups)
        ]
        weights = _numbers(raw.get("weights"), f"{where}: weights")
        try:
            return MaxMixture.from_state(components, weights)
        except ValueError as exc:
            raise _Bad(f"{where}: {exc}") from None
    return _decode_factor(raw, where)


def _encode_values(values: gtsam.Values, where: str) -> list:
    out = []
    for key in values.keys():
        for kind, get in (
            ("pose3", values.atPose3),
            ("pose2", values.atPose2),
            ("rot3", values.atRot3),
            ("rot2", values.atRot2),
            ("vector", values.atVector),
        ):
            try:
                value = get(key)
            except RuntimeError:
                continue
            numbers = _encode_measurement(kind, value)
            if not all(math.isfinite(x) for x in numbers):
                raise ValueError(f"{where}: value {_key_name(key)} is not finite")
            out.append([int(key), kind, numbers])
            break
        else:
            raise ValueError(
                f"{where}: value {_key_name(key)} has a type that "
                f"cannot be saved (saved: Pose2, Pose3, Rot2, Rot3, vectors, points)"
            )
    return out


def _decode_values(raw, where: str) -> gtsam.Values:
    if not isinstance(raw, list):
        raise _Bad(f"{where}: values must be a list")
    values = gtsam.Values()
    for entry in raw:
        if not (
            isinstance(entry, list)
            and len(entry) == 3
            and _is_key(entry[0])
            and entry[1] in ("pose3", "pose2", "rot3", "rot2", "vector")
        ):
            raise _Bad(f"{where}: a value must be [key, kind, numbers], got {str(entry)[:80]}")
        key, kind, numbers = entry
        label = f"{where}, value {_key_name(key)}"
        if values.exists(key):
            raise _Bad(f"{label}: key given twice")
        values.insert(key, _decode_measurement(kind, _numbers(numbers, label), label))
    return values


def _decode_step(raw, where: str) -> tuple[float, list, gtsam.Values]:
    if not isinstance(raw, dict):
        raise _Bad(f"{where}: must be an object")
    t = raw.get("time")
    if not _is_number(t):
        raise _Bad(f"{where}: time must be a finite number, got {t!r}")
    items = raw.get("items")
    if not isinstance(items, list):
        raise _Bad(f"{where}: items must be a list")
    decoded = [_decode_item(item, f"{where}, item {j}") for j, item in enumerate(items)]
    return float(t), decoded, _decode_values(raw.get("values"), where)


def _is_key(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and 0 <= x < 2**64


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _numbers(raw, where: str) -> list:
    if not isinstance(raw, list) or not all(_is_number(x) for x in raw) or len(raw) > 4096:
        raise _Bad(f"{where}: expected a list of finite numbers, got {str(raw)[:80]}")
    return [float(x) for x in raw]


def _dim(raw, where: str) -> int:
    if not (isinstance(raw, int) and not isinstance(raw, bool) and 1 <= raw <= 64):
        raise _Bad(f"{where}: noise dimension must be an integer in [1, 64], got {raw!r}")
    return raw


def _key_name(key: int) -> str:
    """GTSAM's name of a key (x0, l3, ...), or the number when GTSAM cannot format it (a
    symbol character that is not text raises UnicodeDecodeError in DefaultKeyFormatter)."""
    try:
        return gtsam.DefaultKeyFormatter(key)
    except UnicodeDecodeError:
        return str(key)


def _value(values: gtsam.Values, key: int):
    """The entry of `values` at `key` as its own type (Pose3, Pose2, Point3 / vector)."""
    for get in (values.atPose3, values.atPose2, values.atPoint3, values.atVector):
        try:
            return get(key)
        except RuntimeError:
            continue
    raise ValueError(f"no estimate for key {_key_name(key)}")


def _first_line(exc: Exception) -> str:
    """The first non-empty line of a GTSAM exception's message (they run to a page)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return lines[0] if lines else type(exc).__name__


def _subset(values: gtsam.Values, keys: Iterable[int]) -> gtsam.Values:
    """The entries of `values` at `keys` (unknown keys raise ValueError)."""
    wanted = set(keys)
    missing = [_key_name(k) for k in wanted if not values.exists(k)]
    if missing:
        raise ValueError(f"no estimate for keys {missing[:5]}")
    out = gtsam.Values(values)
    for k in values.keys():
        if k not in wanted:
            out.erase(k)
    return out
