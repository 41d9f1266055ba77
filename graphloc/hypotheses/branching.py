"""The geometry of one branching of `graphloc.hypotheses.pose_graph`: factors of a measurement's
candidates, the rigid move of a trajectory's tail when a bridge edge changes candidate (so the
switched hypothesis starts at its own optimum), the predicted chi-square of new factors under
each combination of candidates, and a fresh iSAM2 from a factor list (GTSAM's ISAM2 cannot be
cloned). Bridge edges: docs/design_algorithms.md, "Branching"."""

from __future__ import annotations

import itertools
import math

import gtsam
import numpy as np


def pose_of(values: np.ndarray, dim: int):
    """Pose2 from (x, y, theta) or Pose3 from (x, y, z, qx, qy, qz, qw)."""
    if dim == 2:
        return gtsam.Pose2(*map(float, values))
    x, y, z, qx, qy, qz, qw = map(float, values)
    return gtsam.Pose3(gtsam.Rot3.Quaternion(qw, qx, qy, qz), gtsam.Point3(x, y, z))


def noise_of(information, sigmas, dim: int):
    """A Gaussian noise model from an information matrix, else diagonal `sigmas`."""
    if information is not None:
        return gtsam.noiseModel.Gaussian.Information(np.asarray(information, float))
    return gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, float))


def candidate_factors(
    m, source: int, target: int, dim: int, sigmas, dof: float = math.inf
) -> tuple[list, list]:
    """(candidate poses, one between factor per candidate) of a measurement with
    `candidates` and `information` (graphloc.datasets.pose_graph_file.Measurement); with a
    finite `dof`, each factor's noise is heavy-tailed (`heavy_tailed`)."""
    poses = [pose_of(v, dim) for v in m.candidates]
    infos = m.information or [None] * len(poses)
    noises = [heavy_tailed(noise_of(i, sigmas, dim), dof) for i in infos]
    factors = [between(dim, source, target, p, n) for p, n in zip(poses, noises)]
    return poses, factors


def heavy_tailed(noise, dof: float):
    """`noise` (Gaussian) under GTSAM's Cauchy loss with k^2 = `dof` on its whitened residual
    norm (`gtsam.noiseModel.Robust`), Gaussian for an infinite `dof`: twice the factor's error
    is then dof * log(1 + m / dof) for a Mahalanobis^2 m, -2 log of a multivariate Student-t
    with `dof` degrees of freedom up to the factor (dof + d) / dof, so it equals the Gaussian
    chi-square m to first order near 0 and grows only logarithmically far out (a P3P
    solution far outside its first-order covariance, seed 004 Sec. III)."""
    if math.isinf(dof):
        return noise
    cauchy = gtsam.noiseModel.mEstimator.Cauchy.Create(math.sqrt(dof))
    return gtsam.noiseModel.Robust.Create(cauchy, noise)


def covariance_of(factor) -> np.ndarray:
    """The covariance of a factor's Gaussian noise (under its robust loss, if any)."""
    noise = factor.noiseModel()
    if isinstance(noise, gtsam.noiseModel.Robust):
        noise = noise.noise()
    return noise.covariance()


def robust_chi2(factor, chi2: float) -> float:
    """A factor's chi-square contribution (twice its error) at Mahalanobis^2 `chi2`: `chi2`
    itself for a Gaussian noise, its robust loss otherwise (monotone, so it maps a lower bound
    of the Gaussian rise to a lower bound of the robust one: with the loss rho concave,
    rho(0) = 0 and rho' <= 1, q + rho(m) >= rho(q + m) for any prior rise q >= 0)."""
    noise = factor.noiseModel()
    if not isinstance(noise, gtsam.noiseModel.Robust):
        return chi2
    return 2.0 * float(noise.loss(chi2))


def between(dim: int, key_a: int, key_b: int, pose, noise):
    cls = gtsam.BetweenFactorPose2 if dim == 2 else gtsam.BetweenFactorPose3
    return cls(key_a, key_b, pose, noise)


def prior(dim: int, key: int, pose, noise):
    cls = gtsam.PriorFactorPose2 if dim == 2 else gtsam.PriorFactorPose3
    return cls(key, pose, noise)


def estimate_of(isam: gtsam.ISAM2, key: int, dim: int):
    return isam.calculateEstimatePose2(key) if dim == 2 else isam.calculateEstimatePose3(key)


def insert(values: gtsam.Values, key: int, pose) -> None:
    values.insert(key, pose)


def tail_moves(bridges, choices: dict, poses) -> list:
    """[(position, G)] in position order: the rigid moves of the tails behind the bridges whose
    choice changes. `bridges`: [(position of a, key a, position of b, key b, candidate poses,
    current index)] in position order, `choices`: bridge index in that list -> new index,
    `poses`: key -> current pose (read for a and b only). The moves compose: the tail behind a
    later bridge moves with the earlier ones."""
    moves = []
    for i, (pos_a, key_a, pos_b, key_b, candidates, current) in enumerate(bridges):
        new = choices.get(i, current)
        if new == current:
            continue
        t_a, t_b = moved(poses[key_a], pos_a, moves), moved(poses[key_b], pos_b, moves)
        moves.append((pos_b, t_a.compose(candidates[new]).compose(t_b.inverse())))
    return moves


def moved(pose, position: int, moves: list):
    """`pose` (at `position`) after the rigid moves of every tail it belongs to."""
    for start, g in moves:
        if position >= start:
            pose = g.compose(pose)
    return pose


def predicted_chi2(factors, keys_positions: dict, poses: dict, moves: list) -> float:
    """Twice the error (chi-square) of `factors` at the current poses moved by `moves`."""
    values = gtsam.Values()
    for key, position in keys_positions.items():
        values.insert(key, moved(poses[key], position, moves))
    return float(sum(2.0 * f.error(values) for f in factors))


def combinations(sizes: list[int], limit: int):
    """Every combination of indices for choices with `sizes` options, at most `limit` of
    them (itertools.product order)."""
    return list(itertools.islice(itertools.product(*[range(n) for n in sizes]), limit))


def fresh_isam(params: gtsam.ISAM2Params, graph: gtsam.NonlinearFactorGraph, values):
    """An iSAM2 holding `graph` linearized at `values` (one batch elimination)."""
    isam = gtsam.ISAM2(params)
    isam.update(graph, values)
    return isam


def moved_values(estimate: gtsam.Values, order: list[int], moves: list, dim: int) -> gtsam.Values:
    """`estimate` with every pose behind a switched bridge moved rigidly (`order`: keys by
    insertion position)."""
    if not moves:
        return estimate
    first = moves[0][0]
    out = gtsam.Values(estimate)
    get = out.atPose2 if dim == 2 else out.atPose3
    for position in range(first, len(order)):
        key = order[position]
        if out.exists(key):  # not the poses the current step introduces
            out.update(key, moved(get(key), position, moves))
    return out


def chain_covariance(chain: list, covariances: list) -> np.ndarray:
    """Covariance of the relative pose first -> last of a chain of poses (`chain`, current
    estimates) from its edges' covariances (`covariances[k]`: the edge into chain[k + 1]),
    first order: perturbing edge k by xi moves the last pose by Ad(T_last^-1 T_(k+1)) xi.
    With every other factor dropped it bounds the relative pose's covariance in the whole
    graph from above (information only adds), so a Mahalanobis distance under it is a lower
    bound."""
    if isinstance(chain, np.ndarray) or isinstance(chain[0], gtsam.Pose2):
        return _chain_covariance_2d(chain, covariances)
    last_inverse = chain[-1].inverse()
    total = np.zeros_like(covariances[0])
    for pose, cov in zip(chain[1:], covariances):
        ad = last_inverse.compose(pose).AdjointMap()
        total += ad @ cov @ ad.T
    return total


def lower_bound_chi2(factor, values: gtsam.Values, chain: list, covariances: list) -> float:
    """A lower bound of the rise of the optimal chi-square when `factor` (a between factor
    closing the chain) joins a graph whose optimum is `values` (first order): its residual r
    under its own covariance plus the chain's, r^T (C + Sigma_chain)^-1 r (the rise is r^T (C +
    Sigma_rel)^-1 r for the true relative covariance Sigma_rel <= Sigma_chain)."""
    r = np.asarray(factor.unwhitenedError(values), float)
    cov = covariance_of(factor) + chain_covariance(chain, covariances)
    return robust_chi2(factor, float(r @ np.linalg.solve(cov, r)))


def chain_poses_2d(pose, order: list, first: int, last: int, moves: list) -> np.ndarray:
    """(x, y, theta) of the poses at positions first..last (`pose(key)`), each after the rigid
    moves of the tails it belongs to (`moved`, in NumPy)."""
    xyt = np.array([[p.x(), p.y(), p.theta()] for p in map(pose, order[first : last + 1])])
    position = np.arange(first, last + 1)
    for start, g in moves:
        rows = position >= start
        c, s = np.cos(g.theta()), np.sin(g.theta())
        x, y = xyt[rows, 0].copy(), xyt[rows, 1].copy()
        xyt[rows, 0] = g.x() + c * x - s * y
        xyt[rows, 1] = g.y() + s * x + c * y
        xyt[rows, 2] += g.theta()
    return xyt


def _chain_covariance_2d(chain, covariances: list) -> np.ndarray:
    """`chain_covariance` for Pose2 in NumPy (`chain`: Pose2s or (x, y, theta) rows): Ad of
    (x, y, theta) is [[c, -s, y], [s, c, -x], [0, 0, 1]] (GTSAM's Pose2::AdjointMap)."""
    if isinstance(chain, np.ndarray):
        xyt = chain
    else:
        xyt = np.array([[p.x(), p.y(), p.theta()] for p in chain])
    c, s = np.cos(xyt[-1, 2]), np.sin(xyt[-1, 2])
    d = xyt[1:, :2] - xyt[-1, :2]
    rx, ry = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    rt = xyt[1:, 2] - xyt[-1, 2]
    ad = np.zeros((len(rt), 3, 3))
    ad[:, 0, 0] = ad[:, 1, 1] = np.cos(rt)
    ad[:, 1, 0] = np.sin(rt)
    ad[:, 0, 1] = -ad[:, 1, 0]
    ad[:, 0, 2], ad[:, 1, 2], ad[:, 2, 2] = ry, -rx, 1.0
    return np.einsum("nij,njk,nlk->il", ad, np.asarray(covariances), ad)


def marginal_bound_chi2(factor, values: gtsam.Values, cov_a, cov_b) -> float:
    """The lower bound of `lower_bound_chi2` from the two poses' marginal covariances instead
    of a chain: the relative pose z = T_a^-1 T_b moves by -Ad(z^-1) xi_a + xi_b, and for any
    two jointly Gaussian vectors cov(u + v) <= 2 cov(u) + 2 cov(v), so Sigma_rel <= 2 Ad
    Sigma_a Ad^T + 2 Sigma_b whatever their correlation."""
    keys = factor.keys()
    get = values.atPose2 if len(cov_a) == 3 else values.atPose3
    a, b = get(keys[0]), get(keys[1])
    ad = a.between(b).inverse().AdjointMap()
    r = np.asarray(factor.unwhitenedError(values), float)
    cov = covariance_of(factor) + 2.0 * (ad @ cov_a @ ad.T + cov_b)
    return robust_chi2(factor, float(r @ np.linalg.solve(cov, r)))


def marginals(isam, estimate, pose, order: list, position: dict, edge_cov: list):
    """key -> marginal covariance in a branch's iSAM2 (a pose not in it yet: its predecessor's
    propagated through the edge between them, `edge_cov` by insertion position), cached for
    one branching; None where an edge's covariance is unknown."""
    cache = {}

    def marginal(key):
        if key not in cache:
            if estimate.exists(key):
                cache[key] = isam.marginalCovariance(key)
            else:
                q = position[key]
                before = marginal(order[q - 1]) if q > 0 else None
                if before is None or edge_cov[q] is None:
                    cache[key] = None
                else:
                    ad = pose(order[q - 1]).between(pose(key)).inverse().AdjointMap()
                    cache[key] = ad @ before @ ad.T + edge_cov[q]
        return cache[key]

    return marginal
