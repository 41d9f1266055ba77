"""The two multi-hypothesis engines on the same candidate-set streams (issue 51: can the team
graph's candidate sets move onto the pose-graph engine?): the HypothesisTracker
(`benchmarks.hypotheses.make_engine("tracker")`) and `PoseGraphHypotheses` behind the tracker's
interface (`benchmarks.pose_graph_stream.PoseGraphStream`), in a few configurations
(`ENGINES`), each run simulated once and fed to every method, judged by
`benchmarks.hypotheses.evaluate` (seed 000 Sec. VI-B's lock statistics) plus the CPU time of
the whole run per method (`time.process_time`).

Inputs:
- "feng": seed 000 (000_05137a0a9c449be3.txt) Sec. VI-B, Table III's runs
  (`benchmarks.hypotheses.trial`'s seeds and simulation: FengProbabilisticScenario, 3 ground
  robots seen from a ceiling climber, P3P sets of 2 or 4 candidates, 15 % odometry noise), the
  cells of `benchmarks.hypotheses.CELLS`;
- "kaushik": seed 004 (004_fa12d1d18dcbd0db.txt) Sec. III's tracks (LED triangle under an
  overhead camera, `graphloc.datasets.kaushik.simulate`), the P3P sets of every frame made as
  the Feng runs make theirs (`graphloc.vision.marker_poses.p3p_candidate_sets`), the odometry's
  covariance `graphloc.datasets.feng.odometry_covariance`; cells (focal length, pixel noise).
Used by scripts/bench_candidate_engines.py.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from benchmarks.hypotheses import CELLS, TableIIIConfig, evaluate, make_engine, odometry_steps
from benchmarks.pose_graph_stream import PoseGraphStream
from graphloc.datasets.feng import (
    FengProbabilisticConfig,
    FengProbabilisticScenario,
    odometry_covariance,
)
from graphloc.datasets.kaushik import KaushikConfig, simulate
from graphloc.hypotheses import TrackerConfig
from graphloc.hypotheses.pose_graph import PoseGraphConfig
from graphloc.seams import Odometry
from graphloc.vision.marker_poses import p3p_candidate_sets

DOF = TrackerConfig().student_dof  # the "_t" methods: the tracker's Student-t on candidates
COMMIT_MARGIN = 6.0  # ~ 2 ln 19: the chi-square gap of the tracker's commit posterior 0.95
# method -> (PoseGraphConfig, null) of a PoseGraphStream; "tracker" is the tracker
ENGINES = {
    "pose_graph_default": (PoseGraphConfig(), "all"),
    "pose_graph_window1": (PoseGraphConfig(window=1), "all"),
    "pose_graph_window1_partial": (PoseGraphConfig(window=1), "partial"),
    "pose_graph_window1_none": (PoseGraphConfig(window=1), "none"),
    "pose_graph_window1_t": (PoseGraphConfig(window=1, candidate_dof=DOF), "all"),
    "pose_graph_window1_t_margin6": (
        PoseGraphConfig(window=1, candidate_dof=DOF, margin=COMMIT_MARGIN),
        "all",
    ),
}
QUICK_ENGINES = ("pose_graph_default", "pose_graph_window1_partial", "pose_graph_window1_t_margin6")
KAUSHIK_CELLS = [(16.0, 10.0), (36.0, 3.0)]  # (focal [mm], pixel noise variance [px^2])
KAUSHIK_FRAMES = 60


def engine_settings(method: str) -> dict:
    """The settings of a method that differ from the engine's defaults (for the doc)."""
    if method == "tracker":
        return {"max_hypotheses": TableIIIConfig().max_hypotheses}
    config, null = ENGINES[method]
    default = PoseGraphConfig()
    out = {k: v for k, v in vars(config).items() if v != getattr(default, k)}
    return {**out, "null": null}


def make_method(method: str, ceiling: str = "level"):
    if method == "tracker":
        return make_engine("tracker", ceiling, TableIIIConfig(), 0)
    config, null = ENGINES[method]
    return PoseGraphStream(replace(config), null)


def run_methods(methods, run, odometry, ceiling: str = "level") -> dict:
    """{method: evaluate's statistics of one run + cpu_s (the whole run's CPU time)}."""
    out = {}
    for method in methods:
        start = time.process_time()
        result = evaluate(make_method(method, ceiling), run, odometry)
        result["cpu_s"] = time.process_time() - start
        out[method] = result
    return out


def feng_trial(ceiling: str, curve: str, run_index: int, methods) -> dict:
    """One Table III run (`benchmarks.hypotheses.trial`'s seed and simulation) through every
    method."""
    seed = 1000 * CELLS.index((ceiling, curve)) + run_index
    sim = FengProbabilisticConfig(ceiling=ceiling, curve=curve, seed=seed)
    run = FengProbabilisticScenario.simulate(sim)
    head = {"input": "feng", "cell": f"{ceiling}/{curve}", "run": run_index, "seed": seed}
    return {**head, **run_methods(methods, run, odometry_steps(run, sim), ceiling)}


class KaushikTrack:
    """One seed 004 track as `evaluate` reads a run: candidates (P3P sets with meta["genuine"]),
    t_wc (true camera centres), times."""

    def __init__(self, config: KaushikConfig):
        runs = simulate(replace(config, runs=1))
        self.times, self.t_wc = runs.times, runs.t_wc[0]
        self.candidates = p3p_candidate_sets(
            config.camera(),
            list(runs.pixels[0]),
            [np.arange(3)] * config.frames,
            runs.leds,
            runs.times,
            config.pixel_sigma,
            truth_t=self.t_wc,
        )
        self.odometry = [None] + [
            Odometry(o, odometry_covariance(o, config.odometry_noise, config.odometry_rot_sigma))
            for o in runs.odometry[0]
        ]

    def __len__(self) -> int:
        return len(self.times)


def kaushik_trial(focal_mm: float, noise: float, run_index: int, methods) -> dict:
    """One seed 004 track of `KAUSHIK_FRAMES` frames (seed 100000 + 1000 x cell + run)."""
    seed = 100_000 + 1000 * KAUSHIK_CELLS.index((focal_mm, noise)) + run_index
    config = KaushikConfig(focal_mm=focal_mm, noise_variance=noise, frames=KAUSHIK_FRAMES)
    track = KaushikTrack(replace(config, seed=seed))
    cell = f"{focal_mm:g} mm/{noise:g} px^2"
    head = {"input": "kaushik", "cell": cell, "run": run_index, "seed": seed}
    return {**head, **run_methods(methods, track, track.odometry)}


GROWTH_METHODS = ("tracker", "pose_graph_window1_t_margin6")


def growth_run(ceiling: str, max_time: float, method: str, seed: int = 7) -> dict:
    """CPU per update along one long run (seed 000's setup on the "loop" curve, `max_time`
    seconds): medians and 95th percentiles of the first and the last tenth of the updates (does
    an update's cost grow with the run?), the run's total CPU and its lock statistics
    (`benchmarks.hypotheses.lock_statistics` through `evaluate`'s rule)."""
    sim = FengProbabilisticConfig(ceiling=ceiling, curve="loop", max_time=max_time, seed=seed)
    run = FengProbabilisticScenario.simulate(sim)
    engine, cpu = make_method(method, ceiling), []
    timed = _Timed(engine, cpu)
    result = evaluate(timed, run, odometry_steps(run, sim))
    ms, tenth = 1e3 * np.asarray(cpu), max(1, len(cpu) // 10)
    return {
        "ceiling": ceiling,
        "method": method,
        "frames": len(run),
        "first_tenth_p50_ms": float(np.median(ms[:tenth])),
        "first_tenth_p95_ms": float(np.percentile(ms[:tenth], 95)),
        "last_tenth_p50_ms": float(np.median(ms[-tenth:])),
        "last_tenth_p95_ms": float(np.percentile(ms[-tenth:], 95)),
        "cpu_s": float(ms.sum() / 1e3),
        "correct_lock": result["correct_lock"],
        "wrong_locked_frames": result["wrong_locked_frames"],
        "locked_frames": result["locked_frames"],
    }


class _Timed:
    """An engine whose updates' CPU times (`time.process_time`) are appended to `cpu`."""

    def __init__(self, engine, cpu: list):
        self.engine, self.cpu = engine, cpu

    def update(self, candidates, odometry=None):
        start = time.process_time()
        decision = self.engine.update(candidates, odometry)
        self.cpu.append(time.process_time() - start)
        return decision


def jobs(inputs, runs: int) -> list[tuple]:
    """(trial function, cell arguments, run index) of every run of every input."""
    cells = {"feng": (feng_trial, CELLS), "kaushik": (kaushik_trial, KAUSHIK_CELLS)}
    return [
        (cells[name][0], cell, index)
        for name in inputs
        for cell in cells[name][1]
        for index in range(runs)
    ]


def summarize(trials: list[dict], methods) -> list[dict]:
    """One row per (input, cell, method): the statistics of `benchmarks.hypotheses.summarize`
    that the comparison needs, the locked frames' share of all frames, and CPU seconds."""
    rows = []
    cells = list(dict.fromkeys((t["input"], t["cell"]) for t in trials))
    for source, cell in cells:
        runs = sorted(
            (t for t in trials if (t["input"], t["cell"]) == (source, cell)),
            key=lambda t: t["run"],
        )
        for method in methods:
            res = [t[method] for t in runs]
            correct = [r["correct_lock"] for r in res if r["correct_lock"] is not None]
            locked = sum(r["locked_frames"] for r in res)
            pooled = [(r["rmse_locked"], r["locked_frames"]) for r in res if r["rmse_locked"]]
            rows.append(
                {
                    "input": source,
                    "cell": cell,
                    "method": method,
                    "runs": len(res),
                    "mean_updates_to_correct_lock": float(np.mean(correct)) if correct else None,
                    # a run never correctly locked counts with its whole length (a lower bound)
                    "mean_updates_to_correct_lock_censored": float(
                        np.mean(
                            [
                                r["frames"] - 1 if r["correct_lock"] is None else r["correct_lock"]
                                for r in res
                            ]
                        )
                    ),
                    "never_correct": sum(r["correct_lock"] is None for r in res),
                    "wrong_locks": sum(r["wrong"] for r in res),
                    "wrong_locked_frame_fraction": sum(r["wrong_locked_frames"] for r in res)
                    / locked
                    if locked
                    else None,
                    "locked_frame_share": locked / sum(r["frames"] for r in res),
                    "rmse_locked_frames_m": float(
                        np.sqrt(sum(e * e * n for e, n in pooled) / sum(n for _, n in pooled))
                    )
                    if pooled
                    else None,
                    "mean_latency_ms": float(np.mean([r["mean_latency_ms"] for r in res])),
                    "cpu_s": float(sum(r["cpu_s"] for r in res)),
                }
            )
    return rows


def verdict(rows: list[dict]) -> list[dict]:
    """Per (input, cell, pose-graph method): does it reach a correct lock in at most as many
    updates as the tracker (the censored mean: a run never correctly locked counts with its
    length) with no more wrong locks, and its CPU time over the tracker's."""
    tracker = {(r["input"], r["cell"]): r for r in rows if r["method"] == "tracker"}
    out = []
    for r in rows:
        if r["method"] == "tracker":
            continue
        t = tracker[(r["input"], r["cell"])]
        faster = (
            r["mean_updates_to_correct_lock_censored"] <= t["mean_updates_to_correct_lock_censored"]
        )
        out.append(
            {
                "input": r["input"],
                "cell": r["cell"],
                "method": r["method"],
                "updates_to_correct_lock_vs_tracker": r["mean_updates_to_correct_lock_censored"]
                - t["mean_updates_to_correct_lock_censored"],
                "wrong_locks_vs_tracker": r["wrong_locks"] - t["wrong_locks"],
                "as_good": bool(faster and r["wrong_locks"] <= t["wrong_locks"]),
                "cpu_ratio": r["cpu_s"] / t["cpu_s"] if t["cpu_s"] > 0 else None,
            }
        )
    return out


def plot(rows: list[dict], path) -> None:
    """Grouped bars: mean updates to the first correct lock (censored) per cell and method."""
    from graphloc.plots import plt

    cells = list(dict.fromkeys((r["input"], r["cell"]) for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    value = {(r["input"], r["cell"], r["method"]): r for r in rows}
    fig, ax = plt.subplots(figsize=(max(8.0, 1.6 * len(cells)), 4.5))
    width = 0.8 / len(methods)
    x = np.arange(len(cells))
    for i, method in enumerate(methods):
        heights = [value[(s, c, method)]["mean_updates_to_correct_lock_censored"] for s, c in cells]
        ax.bar(x - 0.4 + width * (i + 0.5), heights, width, label=method.replace("_", " "))
    ax.set_xticks(x, [f"{s}\n{c}" for s, c in cells], fontsize=8)
    ax.set_ylabel("mean updates to first correct lock\n(never: run length)")
    ax.set_title("HypothesisTracker vs PoseGraphHypotheses on the same candidate streams")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
