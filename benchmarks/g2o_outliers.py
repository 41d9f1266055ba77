"""Outlier loop closures injected into public g2o pose graphs (scripts/bench_g2o_outliers.py):
graphloc's engine online (every loop closure with a null component) beside GNC (batch, TLS),
both against the optimum of the graph without outliers.

The generator (seeded, numpy's default_rng): `rate` x (the file's loop closures) false loop
closures between two random poses at least 2 apart, a relative pose drawn uniformly (2D:
x, y in [-5, 5] m, theta in [-pi, pi); 3D: translation in [-5, 5]^3 m, a uniform random
rotation), with the information matrix of the file's first loop closure (as Suenderhauf's
Vertigo generator does with random loop closures). Not installed with graphloc."""

from __future__ import annotations

import time
from dataclasses import replace

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X

from graphloc.datasets.pose_graph_file import Measurement, group_steps, read_pose_graph
from graphloc.hypotheses import branching as br
from graphloc.hypotheses.pose_graph import PoseGraphConfig, PoseGraphHypotheses


def is_loop(m: Measurement) -> bool:
    return abs(m.target - m.source) != 1


def inject(graph, rate: float, seed: int):
    """(measurements with every loop closure null-flagged and the false ones appended, a bool
    per measurement: injected)."""
    rng = np.random.default_rng(seed)
    loops = [m for m in graph.measurements if is_loop(m)]
    n = int(round(rate * len(loops)))
    ids = sorted({k for m in graph.measurements for k in (m.source, m.target)})
    info = loops[0].information
    out = [replace(m, null=True) if is_loop(m) else m for m in graph.measurements]
    fake = []
    for _ in range(n):
        j = int(rng.integers(2, len(ids)))
        i = int(rng.integers(0, j - 1))
        if graph.dim == 2:
            pose = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi)])
        else:
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            pose = np.array([*rng.uniform(-5, 5, 3), *q])
        fake.append(Measurement(-1, ids[i], ids[j], (pose,), info, True))
    return out + fake, [False] * len(out) + [True] * len(fake)


def _prior(dim: int, key: int, pose):
    noise = gtsam.noiseModel.Isotropic.Sigma(3 if dim == 2 else 6, 1e-4)
    return br.prior(dim, key, pose, noise)


def _factor(m: Measurement, dim: int):
    return br.candidate_factors(m, X(m.source), X(m.target), dim, None)[1][0]


def _chain(measurements, dim: int, first: int, start) -> gtsam.Values:
    """Initial values: the odometry edges composed from the first pose."""
    values, poses = gtsam.Values(), {first: start}
    for m in sorted((m for m in measurements if not is_loop(m)), key=lambda m: m.target):
        if m.source in poses and m.target not in poses:
            poses[m.target] = poses[m.source].compose(br.pose_of(m.candidates[0], dim))
    for k, p in poses.items():
        values.insert(X(k), p)
    return values


def positions(values: gtsam.Values, ids: list[int], dim: int) -> np.ndarray:
    get = values.atPose2 if dim == 2 else values.atPose3
    if dim == 2:
        return np.array([[get(X(k)).x(), get(X(k)).y()] for k in ids])
    return np.array([get(X(k)).translation() for k in ids])


def first_pose(graph):
    first = min(min(m.source, m.target) for m in graph.measurements)
    start = graph.vertices.get(first)
    return first, (br.pose_of(start, graph.dim) if start is not None else None)


def inlier_graph(graph) -> gtsam.NonlinearFactorGraph:
    """The graph without outliers: the prior on the first pose and every file measurement; its
    `error(values)` is the objective both methods' estimates are scored on."""
    first, start = first_pose(graph)
    start = start or (gtsam.Pose2() if graph.dim == 2 else gtsam.Pose3())
    factors = gtsam.NonlinearFactorGraph()
    factors.add(_prior(graph.dim, X(first), start))
    for m in graph.measurements:
        factors.add(_factor(m, graph.dim))
    return factors


def reference(graph) -> gtsam.Values:
    """The graph without outliers, Levenberg-Marquardt from the file's vertices (else the
    odometry chain) to the optimum's numerical precision."""
    dim = graph.dim
    first, start = first_pose(graph)
    start = start or (gtsam.Pose2() if dim == 2 else gtsam.Pose3())
    factors = inlier_graph(graph)
    initial = gtsam.Values()
    if len(graph.vertices) >= len({k for m in graph.measurements for k in (m.source, m.target)}):
        for k, v in graph.vertices.items():
            initial.insert(X(k), br.pose_of(v, dim))
    else:
        initial = _chain(graph.measurements, dim, first, start)
    params = gtsam.LevenbergMarquardtParams()  # to the optimum's precision: GTSAM's default
    params.setRelativeErrorTol(1e-12)  # relative tolerance (1e-5) stops a millimetre short on
    params.setAbsoluteErrorTol(1e-12)  # sphere2500, more than the methods compared differ
    params.setMaxIterations(100)
    return gtsam.LevenbergMarquardtOptimizer(factors, initial, params).optimize()


def run_graphloc(graph, measurements, progress=None, config=None) -> dict:
    start_cpu = time.process_time()
    first, start = first_pose(graph)
    engine = PoseGraphHypotheses(graph.dim, PoseGraphConfig(**(config or {})))
    engine.start(first, None if start is None else graph.vertices[first])
    times = []
    for step in group_steps(measurements):
        t = time.process_time()
        engine.step(step)
        times.append(time.process_time() - t)
        if progress is not None:
            progress.update(1)
    estimate = engine.finish()
    choices = engine.choices()
    accepted = {i: choices.get(i, 0) == 0 for i, m in enumerate(measurements) if m.null}
    cpu = time.process_time() - start_cpu
    return {"values": estimate, "accepted": accepted, "cpu": cpu, "times": times, **engine.stats}


def run_gnc(graph, measurements) -> dict:
    start_cpu = time.process_time()
    dim = graph.dim
    first, start = first_pose(graph)
    start = start or (gtsam.Pose2() if dim == 2 else gtsam.Pose3())
    factors = gtsam.NonlinearFactorGraph()
    factors.add(_prior(dim, X(first), start))
    inliers, slots = [0], {}
    for i, m in enumerate(measurements):
        if m.null:
            slots[i] = factors.size()
        else:
            inliers.append(factors.size())
        factors.add(_factor(m, dim))
    params = gtsam.GncLMParams()
    params.setLossType(gtsam.GncLossType.TLS)
    params.setKnownInliers(inliers)
    optimizer = gtsam.GncLMOptimizer(factors, _chain(measurements, dim, first, start), params)
    estimate = optimizer.optimize()
    weights = np.asarray(optimizer.getWeights())
    accepted = {i: bool(weights[k] > 0.5) for i, k in slots.items()}
    return {"values": estimate, "accepted": accepted, "cpu": time.process_time() - start_cpu}


def load(path):
    return read_pose_graph(path)
