"""The HypothesisTracker's window update (tracker.py): for every child, the 2-pose graph
PriorFactorPose3(x0; parent) + BetweenFactorPose3(x0, x1; odometry) + PriorFactorPose3(x1;
candidate) solved as `gtsam.GaussNewtonOptimizer` would (same Jacobians, retraction and stopping
rule), all children of a frame in one batched NumPy pass; the child's covariance is the x1
block of the inverse Hessian. The derivation: docs/design_algorithms.md, "The tracker's window"."""

from __future__ import annotations

import numpy as np

from graphloc.hypotheses import se3

RELATIVE_TOL = ABSOLUTE_TOL = 1e-5  # gtsam.GaussNewtonParams' defaults
_I4, _I6 = np.eye(4), np.eye(6)
_sum = np.add.reduce


def window_updates(
    covariance: tuple[np.ndarray, np.ndarray, np.ndarray],
    odometry_adjoint: np.ndarray,
    candidate: tuple[np.ndarray, np.ndarray],
    innovation: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    iterations: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """n windows. covariance: of the parents (n,6,6), of the odometry (6,6) and of the
    candidates (n,6,6); odometry_adjoint: Ad(u^-1) (6,6); candidate:
    R (n,3,3), t (n,3); innovation: the pose (parent u)^-1 candidate, R (n,3,3), t (n,3), its
    Logmap (n,6) and the inverse right Jacobian at minus it (n,6,6), Jr^-1(-xi) =
    Jr^-1(xi) - ad(xi). Returns the children's R (n,3,3), t (n,3), covariance (n,6,6) and the
    Gauss-Newton iterations done."""
    P, Q, C = covariance
    zR, zt = candidate
    iR, it_, xi_c, jc = innovation
    n = len(zR)
    info = np.linalg.inv(np.concatenate([P, Q[None], C]))
    L = np.zeros((n, 18, 18))  # the information of the three factors, block-diagonal
    L[:, :6, :6], L[:, 6:12, 6:12], L[:, 12:, 12:] = info[:n], info[n], info[n + 1 :]
    # the error poses of every window, [E_a, E_b, E_c]: at the start I, I, z^-1 (x0 u)
    E = np.empty((n, 3, 4, 4))
    E[:] = _I4
    E[:, 2, :3, :3] = iRT = iR.transpose(0, 2, 1)
    E[:, 2, :3, 3:] = -(iRT @ it_[:, :, None])
    # the linearization at the start: zero prior and odometry errors
    e = np.zeros((n, 18, 1))
    e[:, 12:, 0] = -xi_c
    A = np.zeros((n, 18, 12))
    A[:, :6, :6] = A[:, 6:12, 6:] = _I6
    A[:, 6:12, :6] = -odometry_adjoint
    A[:, 12:, 6:] = jc
    Le = L @ e
    error, it = 0.5 * float(_sum(e * Le, None)), 0
    if error > 0.0 and iterations > 0:
        # a step (d0, d1) -> the right steps of E_a, E_b, E_c and the left step of E_b
        K = np.zeros((24, 12))
        K[:6, :6] = K[6:12, 6:] = K[12:18, 6:] = _I6
        K[18:, :6] = -odometry_adjoint
        while True:
            At = A.transpose(0, 2, 1)
            delta = np.linalg.solve(At @ (L @ A), -(At @ Le))
            steps = se3.exp((K @ delta).reshape(4 * n, 6)).reshape(n, 4, 4, 4)
            E = E @ steps[:, :3]
            E[:, 1] = steps[:, 3] @ E[:, 1]
            it += 1
            # linearize at the new values (its error decides whether to go on)
            flat = E.reshape(3 * n, 4, 4)
            xi, jr_inv, ad = se3.log(flat[:, :3, :3], flat[:, :3, 3], jacobian=True)
            e = xi.reshape(n, 18, 1)
            jr_inv = jr_inv.reshape(n, 3, 6, 6)
            A[:, :6, :6] = jr_inv[:, 0]
            A[:, 6:12, :6] = (ad.reshape(n, 3, 6, 6)[:, 1] - jr_inv[:, 1]) @ odometry_adjoint
            A[:, 6:12, 6:] = jr_inv[:, 1]
            A[:, 12:, 6:] = jr_inv[:, 2]
            Le = L @ e
            new_error = 0.5 * float(_sum(e * Le, None))
            if it >= iterations or _converged(error, new_error) or not np.isfinite(error):
                break
            error = new_error
    cov = np.linalg.inv(A.transpose(0, 2, 1) @ (L @ A))[:, 6:, 6:]
    Ec = E[:, 2]
    return (
        zR @ Ec[:, :3, :3],
        (zR @ Ec[:, :3, 3:])[:, :, 0] + zt,
        0.5 * (cov + cov.transpose(0, 2, 1)),
        it,
    )


def _converged(current: float, new: float) -> bool:
    """NonlinearOptimizer's checkConvergence with GaussNewtonParams' defaults (errorTol 0)."""
    if new <= 0.0:
        return True
    decrease = current - new
    return decrease / current <= RELATIVE_TOL or decrease <= ABSOLUTE_TOL
