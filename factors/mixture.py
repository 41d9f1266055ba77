"""P3P candidate mixtures (seed 000 Sec. III-B / V, seed 004 Sec. II-C: up to four P3P solutions,
one genuine): one Gaussian component per candidate pose (`component_factors`), combined as a
max-mixture (Olson & Agarwal, RSS 2012), an ordinary factor LM and iSAM2 optimize."""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.robust import Kernel, robust_noise


def candidate_covariances(candidates: CandidateSet, default_sigmas=(0.02, 0.05)) -> np.ndarray:
    """(K,6,6) covariance of every candidate: meta["covariance"] if present, else diagonal."""
    k = len(candidates)
    cov = (
        candidates.covariance
        if candidates.covariance is not None
        else candidates.meta.get("covariance")
    )
    if cov is None:
        rot, trans = (float(s) for s in default_sigmas)
        if not (rot > 0 and trans > 0):
            raise ValueError(
                f"candidate_covariances: default sigmas must be > 0, got {default_sigmas}"
            )
        return np.broadcast_to(np.diag([rot**2] * 3 + [trans**2] * 3), (k, 6, 6)).copy()
    cov = np.asarray(cov, dtype=float)
    if cov.shape != (k, 6, 6):
        raise ValueError(
            f"CandidateSet.meta['covariance'] must be ({k},6,6), got {cov.shape} "
            f"(source={candidates.source!r}, time={candidates.time})"
        )
    check_covariances(
        cov,
        f"CandidateSet.meta['covariance'] (source={candidates.source!r}, time={candidates.time})",
    )
    return cov


def check_covariances(cov: np.ndarray, what: str) -> None:
    """Batched check of (K,n,n) covariances: finite, symmetric, positive definite (ValueError
    naming the first bad index)."""
    if not np.isfinite(cov).all():
        raise ValueError(f"{what}: contains NaN/inf")
    if not cov.size:
        return
    transposed = np.swapaxes(cov, -1, -2)
    if not np.array_equal(cov, transposed):  # exactly symmetric needs no tolerance
        asym = np.abs(cov - transposed).max(axis=(-2, -1))
        bad = np.nonzero(asym > 1e-9 * np.maximum(1.0, np.abs(cov).max(axis=(-2, -1))))[0]
        if bad.size:
            raise ValueError(f"{what}[{bad[0]}]: not symmetric")
    try:  # a Cholesky factorization exists iff positive definite (the cheaper test)
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        bad = np.nonzero(np.linalg.eigvalsh(cov)[..., 0] <= 0)[0]
        raise ValueError(f"{what}[{bad[0] if bad.size else 0}]: not positive definite") from None


def component_factors(
    candidates: CandidateSet,
    observed_key: int,
    observer_key: int | None = None,
    covariances: np.ndarray | None = None,
    kernel: Kernel = Kernel(),
) -> list[gtsam.NoiseModelFactor]:
    """One factor per candidate: BetweenFactorPose3(observer, observed, T_k) or, with
    observer_key None, PriorFactorPose3(observed, T_k); Gaussian noise from `covariances`,
    optionally robust (`factors.robust.Kernel`)."""
    cov = (
        candidate_covariances(candidates)
        if covariances is None
        else np.asarray(covariances, dtype=float)
    )
    if cov.shape != (len(candidates), 6, 6):
        raise ValueError(
            f"component_factors: covariances must be ({len(candidates)},6,6), got {cov.shape}"
        )
    out = []
    for pose, c in zip(candidates.poses(), cov):
        noise = robust_noise(gtsam.noiseModel.Gaussian.Covariance(c), kernel)
        if observer_key is None:
            out.append(gtsam.PriorFactorPose3(observed_key, pose, noise))
        else:
            out.append(gtsam.BetweenFactorPose3(observer_key, observed_key, pose, noise))
    return out


MIN_WEIGHT = (
    1e-300  # a score that underflowed to 0: -log w = 690, never chosen while any other fits
)


def mixture_weights(candidates: CandidateSet) -> np.ndarray:
    """Component weights (K,) of a candidate set: its normalized scores, with scores that
    underflowed to exactly 0 (e.g. exp(-r^2/2 sigma^2) of a bad candidate) floored at MIN_WEIGHT so
    every candidate keeps its component and index (one rule for both mixture kinds)."""
    return np.maximum(candidates.weights(), MIN_WEIGHT)


# ---- max-mixture (Olson & Agarwal, RSS 2012) --------------------------------------------------
class MaxMixture:
    """A max-mixture of K components (Olson & Agarwal, "Inference on networks of mixtures for
    robust robot mapping", RSS 2012, eq. 5): the sum over the mixture is replaced by its largest
    term, so the negative log likelihood is

        error(x) = min_k [ -log w_k + negLogConstant_k + sum_{f in component k} 0.5 ||r_f(x)||^2 ]

    and the factor is linearized at the active (minimizing) component -- an ordinary
    nonlinear factor that LM and iSAM2 can use (unlike `HybridNonlinearFactor`, which needs a
    hybrid solver). `factor` is a `gtsam.CustomFactor` whose residual is the active component's
    whitened error (its built-in factors' `linearize` gives the Jacobians), zero-padded to a
    fixed length, plus one row sqrt(2 (c_k - min_j c_j)) for its constant c_k, so that
    0.5 ||residual||^2 = error(x) - min_j c_j (a constant shift of the error).

    A component is one factor or a group of factors whose errors add; every component must
    touch the same variables. `active(values)` is the chosen mode at `values`;
    `component_errors(values)` all K terms. Under iSAM2 a switch of mode takes effect at the
    next relinearization of its variables (docs/design_algorithms.md).
    """

    def __init__(self, components, weights):
        groups = [tuple(c) if isinstance(c, (list, tuple)) else (c,) for c in components]
        if not groups:
            raise ValueError("max_mixture_factor: no components")
        if any(not g for g in groups):
            raise ValueError(
                f"max_mixture_factor: component {[i for i, g in enumerate(groups) if not g][0]} "
                f"has no factors"
            )
        w = np.asarray(weights, dtype=float)
        if w.shape != (len(groups),):
            raise ValueError(
                f"max_mixture_factor: weights must have shape ({len(groups)},), got {w.shape}"
            )
        bad = np.flatnonzero(~(np.isfinite(w) & (w > 0)))
        if bad.size:
            raise ValueError(
                f"max_mixture_factor: weight[{bad[0]}] = {w[bad[0]]} must be finite and > 0"
            )
        w = w / w.sum()
        keys = []
        for i, group in enumerate(groups):
            for f in group:
                if not isinstance(f, gtsam.NoiseModelFactor):
                    raise ValueError(
                        f"max_mixture_factor: component {i} holds {type(f).__name__}, "
                        f"expected a gtsam NoiseModelFactor"
                    )
                if isinstance(f.noiseModel(), gtsam.noiseModel.Robust):
                    raise ValueError(
                        f"max_mixture_factor: component {i} has a robust noise model; the "
                        f"max-mixture is itself the robust model, use Gaussian components"
                    )
            keys.append(sorted({k for f in group for k in f.keys()}))
        if any(k != keys[0] for k in keys):
            raise ValueError(f"max_mixture_factor: components touch different variables {keys}")
        self.components = tuple(groups)
        self.weights = w
        self.keys = keys[0]
        constants = -np.log(w) + np.array(
            [sum(f.noiseModel().negLogConstant() for f in g) for g in groups]
        )
        self.constants = constants  # (K,) c_k = -log w_k + negLogConstant_k
        self._offset_rows = np.sqrt(2.0 * (constants - constants.min()))
        self._dims = [sum(f.dim() for f in g) for g in groups]
        self.residual_dim = max(self._dims) + 1
        self._key_dims: list[int] | None = None
        self.factor = gtsam.CustomFactor(
            gtsam.noiseModel.Unit.Create(self.residual_dim), self.keys, self._evaluate
        )

    def __reduce__(self):
        """Pickle as (components, weights): the built-in factors pickle, the CustomFactor is
        rebuilt."""
        return (MaxMixture, (self.components, self.weights))

    def component_errors(self, values: gtsam.Values) -> np.ndarray:
        """(K,) c_k + sum of the component's factor errors at `values`."""
        return self.constants + np.array([sum(f.error(values) for f in g) for g in self.components])

    def active(self, values: gtsam.Values) -> int:
        """Index of the component the factor is linearized at (argmin of `component_errors`)."""
        return int(np.argmin(self.component_errors(values)))

    def _evaluate(self, _this, values: gtsam.Values, H):
        k = self.active(values)
        residual = np.zeros(self.residual_dim)
        residual[-1] = self._offset_rows[k]
        if H is None:
            residual[: self._dims[k]] = np.concatenate(
                [f.whitenedError(values) for f in self.components[k]]
            )
            return residual
        if self._key_dims is None:  # once: the tangent dimension of every variable of the factor
            zero = values.zeroVectors()
            self._key_dims = [len(zero.at(key)) for key in self.keys]
        column = dict(zip(self.keys, np.cumsum([0] + self._key_dims[:-1])))
        J = np.zeros((self.residual_dim, sum(self._key_dims)))
        row = 0
        for f in self.components[k]:
            A, b = f.linearize(values).jacobian()  # whitened: A dx - b, b = -whitened error
            residual[row : row + len(b)] = -b
            col = 0
            for key in f.keys():
                d = self._key_dims[self.keys.index(key)]
                J[row : row + len(b), column[key] : column[key] + d] = A[:, col : col + d]
                col += d
            row += len(b)
        for i, key in enumerate(self.keys):
            H[i] = J[:, column[key] : column[key] + self._key_dims[i]]
        return residual


def max_mixture_factor(components, weights) -> MaxMixture:
    """Max-mixture (Olson & Agarwal, RSS 2012) of `components` -- each a NoiseModelFactor or a
    list of them (summed) -- with weights (K,) > 0 (normalized here); see `MaxMixture`. Add
    `.factor` to the graph; keep the object to read `.active(values)`."""
    return MaxMixture(list(components), weights)
