"""Robust kernels chosen by name, per factor type, on top of gtsam.noiseModel.Robust.

    noise = robust_noise(gtsam.noiseModel.Diagonal.Sigmas([0.05, 0.1]), Kernel("cauchy", 1.0))
    muted = residuals(graph, estimate).downweighted(0.5)   # which factors the kernel mutes

Kernels (gtsam.noiseModel.mEstimator): huber, cauchy, tukey, gemanmcclure, dcs, welsch, or none.
`threshold` is the kernel's own constant `k` (in whitened units, i.e. sigmas).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # annotations only
    import gtsam
    import numpy as np

# kernel name -> its class in gtsam.noiseModel.mEstimator (GTSAM loads where a noise model is
# built: `Kernel` and `KernelPolicy` are settings the command line's options are checked with)
KERNELS = {
    "huber": "Huber",
    "cauchy": "Cauchy",
    "tukey": "Tukey",
    "gemanmcclure": "GemanMcClure",
    "dcs": "DCS",
    "welsch": "Welsch",
}


@dataclass(frozen=True)
class Kernel:
    """A robust kernel by name ("none" = plain Gaussian) and its constant k [sigmas]."""

    name: str = "none"
    k: float = 1.345

    def __post_init__(self):
        if not isinstance(self.name, str):
            raise ValueError(f"robust kernel name must be a string, got {self.name!r}")
        name = self.name.lower().replace("-", "").replace("_", "")
        if name != "none" and name not in KERNELS:
            raise ValueError(
                f"unknown robust kernel {self.name!r}; choose from none, {', '.join(KERNELS)}"
            )
        try:
            k = float(self.k)
        except (TypeError, ValueError):
            k = float("nan")
        if not (math.isfinite(k) and k > 0):
            raise ValueError(f"robust kernel constant k must be finite > 0, got {self.k!r}")
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "k", k)

    @classmethod
    def parse(cls, text: str) -> "Kernel":
        """ "cauchy" or "cauchy:1.0" -> Kernel (for command lines and config files); a
        ValueError quoting `text` otherwise."""
        if not isinstance(text, str):
            raise ValueError(f"robust kernel must be NAME[:k] (e.g. cauchy:2.0), got {text!r}")
        name, sep, k = text.strip().partition(":")
        try:
            constant = float(k) if sep else None
        except ValueError:
            raise ValueError(
                f"robust kernel {text!r}: constant {k!r} is not a number (NAME[:k], e.g. "
                f"cauchy:2.0)"
            ) from None
        try:
            return cls(name, constant) if sep else cls(name)
        except ValueError as exc:
            raise ValueError(f"robust kernel {text!r}: {exc}") from None


@dataclass(frozen=True)
class KernelPolicy:
    """Which kernel each factor type gets (factor types: odometry, landmark, inter_robot, prior,
    or any other name a pipeline uses); types not listed get `default`."""

    by_type: dict = field(default_factory=dict)
    default: Kernel = Kernel("none")

    def kernel(self, factor_type: str) -> Kernel:
        return self.by_type.get(factor_type, self.default)


def robust_noise(base: gtsam.noiseModel.Base, kernel: Kernel) -> gtsam.noiseModel.Base:
    """`base` wrapped in gtsam.noiseModel.Robust with `kernel` (returned unchanged for "none")."""
    if kernel.name == "none":
        return base
    import gtsam

    return gtsam.noiseModel.Robust.Create(_estimator(kernel.name, kernel.k), base)


@functools.lru_cache(maxsize=64)
def _estimator(name: str, k: float):
    """The m-estimator of a kernel: one immutable GTSAM object per (name, k), shared by every
    noise model that uses it (a graph builds tens of thousands)."""
    import gtsam

    return getattr(gtsam.noiseModel.mEstimator, KERNELS[name]).Create(k)


@dataclass(frozen=True)
class Residuals:
    """Every factor of a graph judged at one estimate: dims (N,) residual dimension; chi2 (N,)
    the squared whitened residual *without* the robust kernel (the Gaussian measurement
    model's chi-square; a factor with no noise model, e.g. a max-mixture: twice its error);
    weights (N,) the robust kernel's weight w(||whitened residual||) (1 for non-robust
    factors); robust (N,) whether the factor has a kernel."""

    dims: np.ndarray
    chi2: np.ndarray
    weights: np.ndarray
    robust: np.ndarray

    def downweighted(self, threshold: float) -> np.ndarray:
        """(N,) bool: robust factors whose kernel weight is below `threshold`."""
        if not 0 < threshold <= 1:
            raise ValueError(f"down-weight threshold must be in (0, 1], got {threshold}")
        return self.robust & (self.weights < threshold)


UNINFORMATIVE = 1e5  # a residual component with a larger std carries no measurement


def gaussian_part(factor) -> tuple:
    """(noise model, its Gaussian part -- the model itself where it has no kernel --, residual
    dimension counted) of one factor; (None, None, factor.dim()) for a factor without a noise
    model (e.g. a max-mixture). Components of std >= UNINFORMATIVE are not counted."""
    import gtsam
    import numpy as np

    model = factor.noiseModel() if hasattr(factor, "noiseModel") else None
    if model is None:
        return None, None, factor.dim()
    base = model.noise() if isinstance(model, gtsam.noiseModel.Robust) else model
    return model, base, int(np.count_nonzero(np.asarray(base.sigmas()) < UNINFORMATIVE))


def residuals(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> Residuals:
    """`Residuals` of every factor of `graph` at `values` (one pass, in graph order; a removed
    factor slot counts as dimension 0; a residual component of std >= UNINFORMATIVE, e.g. the
    range of a bearing-only `factors.bearing.bearing_factor`, does not count in the
    dimension)."""
    import numpy as np

    n = graph.size()
    dims, chi2, weights = np.zeros(n, int), np.zeros(n), np.ones(n)
    robust = np.zeros(n, bool)
    for i in range(n):
        factor = graph.at(i)
        if factor is None:
            continue
        model, base, dims[i] = gaussian_part(factor)
        if model is None:
            chi2[i] = 2.0 * factor.error(values)
            continue
        whitened = base.whiten(np.asarray(factor.unwhitenedError(values), dtype=float))
        chi2[i] = square = float(whitened @ whitened)
        if base is not model:
            robust[i] = True
            weights[i] = model.robust().weight(math.sqrt(square))
    return Residuals(dims, chi2, weights, robust)


class GaussianChi2:
    """The chi-square without the robust kernels (as `residuals` counts it) of a growing graph,
    in one C++ pass: each factor added is kept as its clone under the kernel's Gaussian model
    (`cloneWithNewNoiseModel`; factors without a kernel as they are), so the sum is twice that
    graph's `error`. A factor GTSAM cannot clone (a Python CustomFactor) is judged factor by
    factor (`residuals`). Use: `chi2 = GaussianChi2(); chi2.add(graph); chi2(values)`."""

    def __init__(self):
        import gtsam

        self.plain = gtsam.NonlinearFactorGraph()  # Gaussian clones and kernel-free factors
        self.loose = gtsam.NonlinearFactorGraph()  # robust factors GTSAM cannot clone
        self._dim = 0  # residual dimension counted (`residuals`' dims)
        self._pending: list = []  # what `add` was given since the last sum: cloned when asked

    @property
    def dim(self) -> int:
        """The residual dimension counted (`residuals`' dims) of every factor added."""
        self._take_pending()
        return self._dim

    def add(self, factors) -> None:
        """Add a NonlinearFactorGraph, or a list of factors, graphs and factor providers (an
        object whose `factor` is the gtsam factor, as `Session.add` takes). The clones are made
        when the sum or `dim` is next asked for (a single online pass never asks)."""
        self._pending.append(factors)

    def _take_pending(self) -> None:
        import gtsam

        pending, self._pending = self._pending, []
        graph = gtsam.NonlinearFactorGraph()
        for factors in pending:
            for item in [factors] if isinstance(factors, gtsam.NonlinearFactorGraph) else factors:
                graph.push_back(getattr(item, "factor", item))
        for i in range(graph.size()):
            factor = graph.at(i)
            if factor is None:
                continue
            model, base, dim = gaussian_part(factor)
            self._dim += dim
            if base is model:  # no kernel (or no noise model): judged as it is
                self.plain.push_back(factor)
            elif isinstance(factor, gtsam.CustomFactor):
                self.loose.push_back(factor)
            else:
                self.plain.push_back(factor.cloneWithNewNoiseModel(base))

    def __call__(self, values: gtsam.Values) -> float:
        self._take_pending()
        chi2 = 2.0 * float(self.plain.error(values))
        if self.loose.size():
            chi2 += float(residuals(self.loose, values).chi2.sum())
        return chi2
