"""The methods scripts/bench_city10000.py runs side by side on City10000 with permuted
candidates, each from the same measurements (graphloc.datasets.pose_graph_file), each timed in
CPU seconds (time.process_time) per step (the edges ending at one new pose) and in total:

* graphloc: graphloc.hypotheses.pose_graph.PoseGraphHypotheses, one `step` per pose;
* HybridSmoother: GTSAM's HybridCity10000 example, its settings (marginal threshold 0.9999, an
  update after every 3 hybrid factors or loop closures, at most 10 hypotheses, a
  relinearization every 10 updates, sigmas 0.05 m / 0.01 rad), its initial guess from each
  edge's first candidate (after the permutation);
* GNC: gtsam.GncLMOptimizer with the truncated least squares loss over every candidate of every
  ambiguous edge, the other factors known inliers, initialized by chaining first candidates
  (batch: its time is one solve);
* the oracle: iSAM2 (GTSAM's default parameters), one update per pose, given the correct
  candidate of every edge.

Not installed with graphloc: a helper of the script only."""

from __future__ import annotations

import time

import gtsam
import numpy as np
from gtsam.symbol_shorthand import M, X

from graphloc.datasets.pose_graph_file import group_steps, permute_candidates, read_pose_graph
from graphloc.hypotheses.pose_graph import PoseGraphConfig, PoseGraphHypotheses

SIGMAS = np.array([1.0 / 20.0, 1.0 / 20.0, 1.0 / 100.0])  # the example's pose_noise_model
PRIOR = gtsam.noiseModel.Diagonal.Sigmas(np.full(3, 1e-4))


def data_file() -> str:
    return gtsam.findExampleDataFile("T1_city10000_04.txt")


def ground_truth() -> np.ndarray:
    return np.loadtxt(gtsam.findExampleDataFile("ISAM2_GT_city10000.txt"))[:, :2]


def load(edges: int | None, seed: int):
    """(measurements with permuted candidates, truth {index: candidate}, steps)."""
    graph = read_pose_graph(data_file(), max_edges=edges)
    measurements, truth = permute_candidates(graph.measurements, seed)
    return measurements, truth, group_steps(measurements)


def positions(values: gtsam.Values, n: int) -> np.ndarray:
    return np.array([[values.atPose2(X(k)).x(), values.atPose2(X(k)).y()] for k in range(n)])


def n_poses(measurements) -> int:
    return 1 + max(max(m.source, m.target) for m in measurements)


def _pose(c) -> gtsam.Pose2:
    return gtsam.Pose2(float(c[0]), float(c[1]), float(c[2]))


def _timed(steps, do, progress=None) -> list[float]:
    times = []
    for step in steps:
        start = time.process_time()
        do(step)
        times.append(time.process_time() - start)
        if progress is not None:
            progress.update(1)
    return times


def run_graphloc(measurements, steps, config: PoseGraphConfig | None = None, progress=None):
    start = time.process_time()
    engine = PoseGraphHypotheses(2, config or PoseGraphConfig(sigmas=tuple(SIGMAS)))
    engine.start(steps[0][0][1].source)
    times = _timed(steps, engine.step, progress)
    estimate = engine.finish()
    total = time.process_time() - start
    xy = positions(estimate, n_poses(measurements))
    return {"xy": xy, "choices": engine.choices(), "cpu": total, "times": times, **engine.stats}


def run_oracle(measurements, steps, truth, progress=None):
    start = time.process_time()
    noise = gtsam.noiseModel.Diagonal.Sigmas(SIGMAS)
    isam = gtsam.ISAM2(gtsam.ISAM2Params())
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(), PRIOR))
    values.insert(X(0), gtsam.Pose2())
    isam.update(graph, values)

    def do(step):
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        for i, m in step:
            z = _pose(m.candidates[truth.get(i, 0)])
            graph.add(gtsam.BetweenFactorPose2(X(m.source), X(m.target), z, noise))
            if m.target == m.source + 1:
                values.insert(X(m.target), isam.calculateEstimatePose2(X(m.source)).compose(z))
        isam.update(graph, values)

    times = _timed(steps, do, progress)
    for _ in range(3):
        isam.update()
    xy = positions(isam.calculateEstimate(), n_poses(measurements))
    return {"xy": xy, "cpu": time.process_time() - start, "times": times}


def run_hybrid(measurements, steps, progress=None, max_hypotheses=10, every=3, relin=10):
    """GTSAM's HybridCity10000 example's loop over the same steps."""
    start = time.process_time()
    pose_noise = gtsam.noiseModel.Diagonal.Sigmas(SIGMAS)
    open_noise = gtsam.noiseModel.Diagonal.Sigmas(np.full(3, 10.0))
    smoother = gtsam.HybridSmoother(0.9999)
    state = {"new": gtsam.HybridNonlinearFactorGraph(), "initial": gtsam.Values(), "n": 0}
    state["initial"].insert(X(0), gtsam.Pose2())
    state["new"].push_back(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(), PRIOR))
    smoother.update(state["new"], state["initial"], max_hypotheses)
    state["new"].resize(0)
    modes, updates = {}, [0]

    def flush():
        smoother.update(state["new"], state["initial"], max_hypotheses)
        state["new"].resize(0)
        updates[0] += 1
        if updates[0] % relin == 0:
            smoother.relinearize()
            state["initial"] = smoother.linearizationPoint()

    def do(step):
        for i, m in step:
            poses = [_pose(c) for c in m.candidates]
            a, b = X(m.source), X(m.target)
            if m.target == m.source + 1:
                if len(poses) > 1:
                    key = (M(len(modes)), len(poses))
                    modes[i] = key[0]
                    constant = pose_noise.negLogConstant()
                    parts = [
                        (gtsam.BetweenFactorPose2(a, b, p, pose_noise), constant) for p in poses
                    ]
                    state["new"].push_back(gtsam.HybridNonlinearFactor(key, parts))
                    state["n"] += 1
                else:
                    state["new"].push_back(gtsam.BetweenFactorPose2(a, b, poses[0], pose_noise))
                state["initial"].insert(b, state["initial"].atPose2(a).compose(poses[0]))
            else:
                if m.null:
                    key = (M(10_000_000 + i), 2)
                    parts = [
                        (gtsam.BetweenFactorPose2(a, b, poses[0], n), n.negLogConstant())
                        for n in (open_noise, pose_noise)
                    ]
                    state["new"].push_back(gtsam.HybridNonlinearFactor(key, parts))
                else:
                    state["new"].push_back(gtsam.BetweenFactorPose2(a, b, poses[0], pose_noise))
                state["n"] += 1
            if state["n"] >= every:
                flush()
                state["n"] = 0

    times = _timed(steps, do, progress)
    flush()
    delta = smoother.optimize()
    estimate = state["initial"].retract(delta.continuous())
    discrete = dict(smoother.fixedValues().items())
    discrete.update(dict(delta.discrete().items()))
    choices = {i: int(discrete.get(key, -1)) for i, key in modes.items()}
    xy = positions(estimate, n_poses(measurements))
    return {"xy": xy, "choices": choices, "cpu": time.process_time() - start, "times": times}


def run_gnc(measurements, progress=None):
    start = time.process_time()
    noise = gtsam.noiseModel.Diagonal.Sigmas(SIGMAS)
    graph, initial = gtsam.NonlinearFactorGraph(), gtsam.Values()
    graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(), PRIOR))
    initial.insert(X(0), gtsam.Pose2())
    inliers, slots = [0], {}
    for i, m in enumerate(measurements):
        poses = [_pose(c) for c in m.candidates]
        if len(poses) > 1:
            slots[i] = []
        for p in poses:
            if len(poses) > 1:
                slots[i].append(graph.size())
            else:
                inliers.append(graph.size())
            graph.add(gtsam.BetweenFactorPose2(X(m.source), X(m.target), p, noise))
        if m.target == m.source + 1:
            initial.insert(X(m.target), initial.atPose2(X(m.source)).compose(poses[0]))
    params = gtsam.GncLMParams()
    params.setLossType(gtsam.GncLossType.TLS)
    params.setKnownInliers(inliers)
    optimizer = gtsam.GncLMOptimizer(graph, initial, params)
    estimate = optimizer.optimize()
    weights = np.asarray(optimizer.getWeights())
    choices = {}
    for i, idx in slots.items():
        errors = [graph.at(k).error(estimate) for k in idx]
        w = weights[idx]
        choices[i] = int(np.argmax(w)) if w.max() - w.min() > 0.5 else int(np.argmin(errors))
    if progress is not None:
        progress.update(1)
    xy = positions(estimate, n_poses(measurements))
    return {"xy": xy, "choices": choices, "cpu": time.process_time() - start, "times": []}


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    n = min(len(a), len(b))
    return float(np.sqrt(np.mean(np.sum((a[:n] - b[:n]) ** 2, axis=1))))


def timing(times: list[float]) -> dict:
    """Per-step CPU milliseconds: p50, p95, and p95 over the first and the last tenth."""
    t = np.asarray(times) * 1e3
    if t.size == 0:
        return {}
    tenth = max(1, t.size // 10)
    first, last = np.percentile(t[:tenth], 95), np.percentile(t[-tenth:], 95)
    return {
        "p50_ms": float(np.median(t)),
        "p95_ms": float(np.percentile(t, 95)),
        "first_tenth_p95_ms": float(first),
        "last_tenth_p95_ms": float(last),
        "growth": float(last / first) if first > 0 else float("inf"),
    }
