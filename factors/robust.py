"""Robust kernels chosen by name, per factor type, on top of gtsam.noiseModel.Robust.

    noise = robust_noise(gtsam.noiseModel.Diagonal.Sigmas([0.05, 0.1]), Kernel("cauchy", 1.0))
    report = downweighted(graph, estimate, threshold=0.5)   # how many factors the kernel muted

Kernels (gtsam.noiseModel.mEstimator): huber, cauchy, tukey, gemanmcclure, dcs, welsch, or none.
`threshold` is the kernel's own constant `k` (in whitened units, i.e. sigmas).
"""

from __future__ import annotations

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

    estimator = getattr(gtsam.noiseModel.mEstimator, KERNELS[kernel.name]).Create(kernel.k)
    return gtsam.noiseModel.Robust.Create(estimator, base)


@dataclass(frozen=True)
class DownweightReport:
    """indices: (n_robust,) graph indices of robust factors; weights: (n_robust,) their kernel
    weights at the evaluated values; n_downweighted: how many have weight < threshold."""

    indices: np.ndarray
    weights: np.ndarray
    threshold: float

    @property
    def n_robust(self) -> int:
        return int(self.indices.size)

    @property
    def n_downweighted(self) -> int:
        return int((self.weights < self.threshold).sum())

    def downweighted_indices(self) -> np.ndarray:
        return self.indices[self.weights < self.threshold]


def downweighted(
    graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, threshold: float = 0.5, indices=None
) -> DownweightReport:
    """Kernel weight w(||whitened residual||) of every robust factor of `graph` (or of the
    factors at `indices`) at `values`; factors with w < threshold count as down-weighted."""
    if not 0 < threshold <= 1:
        raise ValueError(f"down-weight threshold must be in (0, 1], got {threshold}")
    import gtsam
    import numpy as np

    candidates = range(graph.size()) if indices is None else indices
    out_idx, out_w = [], []
    for i in candidates:
        factor = graph.at(int(i))
        if factor is None or not hasattr(factor, "noiseModel"):
            continue
        model = factor.noiseModel()
        if not isinstance(model, gtsam.noiseModel.Robust):
            continue
        whitened = model.noise().whiten(np.asarray(factor.unwhitenedError(values), dtype=float))
        out_idx.append(int(i))
        out_w.append(model.robust().weight(float(np.linalg.norm(whitened))))
    return DownweightReport(
        np.asarray(out_idx, dtype=int), np.asarray(out_w, dtype=float), float(threshold)
    )
