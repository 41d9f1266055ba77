"""The pose-graph engine's final refinement (`PoseGraphHypotheses.finish`): Levenberg-Marquardt
to the optimum's precision, and the measurements with a null component decided again there."""

from __future__ import annotations

import gtsam


def refinement() -> gtsam.LevenbergMarquardtParams:
    """Levenberg-Marquardt to the optimum's numerical precision (GTSAM's default relative
    tolerance, 1e-5 of the error, stops millimetres short on graphs of thousands of poses)."""
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-12)
    params.setMaxIterations(100)
    return params


def redecided(
    graph: gtsam.NonlinearFactorGraph,
    estimate: gtsam.Values,
    ambiguities,
    null_penalty: float,
    rounds: int,
) -> tuple[gtsam.Values, int]:
    """(the re-optimized estimate, how many decisions changed): the decided measurements with a
    null component (`Ambiguity`, its factors ending with None) decided again at the optimum
    `estimate`: each takes the component of least cost there -- a candidate's chi-square
    (2 x its error) or the null's `null_penalty`, what a max-mixture of them chooses --, its
    factor put into or taken out of `graph` (a decided factor sits at its `Ambiguity.slot`),
    and the graph re-optimized, until no decision changes (at most `rounds` times). A loop
    closure is judged at its arrival, against an estimate that may have drifted since the
    previous closure: a true one after a long loop can cost more than the null there, and an
    outlier can fit a drifted estimate; both show at the optimum of the other decisions (an
    alternation of decisions and estimate, as EM)."""
    changed = 0
    for _ in range(rounds):
        now = 0
        for amb in ambiguities:
            if amb.state != "decided" or amb.factors[-1] is not None:
                continue  # undecided, or no null component
            costs = [
                (null_penalty if f is None else 2.0 * f.error(estimate), k)
                for k, f in enumerate(amb.factors)
            ]
            best = min(costs)[1]
            if best == amb.choice:
                continue
            now += 1
            amb.choice = best
            factor = amb.factors[best]
            if factor is None:
                graph.remove(amb.slot)
            elif amb.slot >= 0:
                graph.replace(amb.slot, factor)
            else:
                amb.slot = graph.size()
                graph.add(factor)
        changed += now
        if not now:
            break
        estimate = gtsam.LevenbergMarquardtOptimizer(graph, estimate, refinement()).optimize()
    return estimate, changed
