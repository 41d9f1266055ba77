"""Benchmark: the `crawler-pair` scenario (seed 003, 003_8db27855ce2d5f68.txt, Sec. III / Fig. 6)
through the front door -- the log `graphloc simulate crawler-pair` writes, read by
`graphloc.datasets.open_run`, built by `graphloc.runner.team_run.team_graph` (the live
builder's event route, `graphloc.live.events`) and solved by `graphloc.pipelines.team_graph`
(what `graphloc smooth` / `online` run) -- beside the seed's EKF
(`benchmarks.baselines.ekf_seed003`) on the same front-end measurements, for N = 1, 2, 10,
20 feature points (N counts the robot tracker's point, so N - 1 KLT tracks).

Per trial one rendered sequence (a different random scene and motion per seed); per N the
front-end (`measure_frames`) runs once and feeds both the EKF and the log writer
(`datasets.crawler_pair_log`). Metric (the seed's Fig. 6 quantity): the mean absolute
translation error per axis of the moving robot's camera over the sequence [mm], no alignment
(world = camera 0 in both); batch = the final smoothed trajectory, online = each frame's
estimate when it arrived (causal, as the filter). Also the circle candidate the max-mixture
chose per sighting against the genuine one.

Target (issue 14): front door batch and online below the EKF on every axis for every N.

    .venv/bin/python scripts/bench_team_crawler.py --trials 2 --out out/team_crawler_quick
    .venv/bin/python scripts/bench_team_crawler.py --out out/team_crawler \
        --doc docs/results_team_crawler.md
"""

from __future__ import annotations

import argparse
import json
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.baselines.ekf_seed003 import EkfConfig, run_ekf
from graphloc.datasets import open_run
from graphloc.datasets.crawler_pair import CrawlerPairConfig, CrawlerPairScenario
from graphloc.datasets.crawler_pair_log import write_crawler_pair_log
from benchmarks.seed003_measures import axis_errors
from benchmarks.trials import TrialExecutor
from benchmarks.markdown import write_report
from benchmarks.render import render
from graphloc.pipelines.judge import genuine_candidates
from graphloc.pipelines.team_graph import GraphConfig, default_lag, solve
from graphloc.runner.team_run import team_graph
from graphloc.plots import plt
from graphloc.structured import dumps_json
from graphloc.vision.features import FeatureConfig
from graphloc.vision.teammate import TeammateConfig, measure_frames

N_VALUES = (1, 2, 10, 20)
METHODS = ("ekf", "batch", "online")
AXES = ("x", "y", "z")
SIZES = {"full": 16, "quick": 2}  # trials


def run_trial(seed: int) -> dict:
    """One rendered sequence through the EKF and the front door for every N; errors in mm."""
    seq = CrawlerPairScenario(CrawlerPairConfig(seed=seed)).render_sequence()
    flags = seq.frame_flags()
    truth = seq.t_wc
    out = {}
    for n in N_VALUES:
        frames, _ = measure_frames(
            seq.images,
            seq.camera,
            *flags,
            FeatureConfig(max_features=n - 1),
            TeammateConfig(radius=seq.config.base_radius),
        )
        ekf = run_ekf(
            frames,
            seq.camera,
            EkfConfig(
                feature_depth=seq.config.background_distance,
                tracker_setting="proper",
                pixel_pitch=seq.config.pixel_pitch,
            ),
        )
        res = {"ekf": 1e3 * axis_errors(ekf, truth).mean(axis=0)}
        with tempfile.TemporaryDirectory() as tmp:
            write_crawler_pair_log(seq, frames, tmp)
            run = open_run(tmp)
        cam = run.index("camera")
        graph = team_graph(run, GraphConfig())  # the verbs' graph (the live builder's)
        for mode in ("batch", "online"):
            config = replace(graph.config, lag=default_lag(run, graph.config))
            result = solve(replace(graph, config=config), mode=mode)
            rows = result.estimate[cam] if mode == "batch" else result.causal[cam]
            res[mode] = 1e3 * axis_errors(rows[:, :3], truth).mean(axis=0)
            genuine = genuine_candidates(run, result.decisions)
            chosen = [(d.committed, g) for d, g in zip(result.decisions, genuine) if g >= 0]
            res[f"{mode}_sightings"] = len(chosen)
            res[f"{mode}_wrong"] = sum(c != g for c, g in chosen)
        out[n] = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in res.items()}
    return out


def summarize(trials: list[dict]) -> dict:
    summary = {}
    for n in N_VALUES:
        cell = {}
        for m in METHODS:
            e = np.array([t[n][m] for t in trials])  # (trials, 3)
            cell[m] = {"mean_mm": e.mean(axis=0).tolist(), "std_mm": e.std(axis=0).tolist()}
        for m in ("batch", "online"):
            cell[m]["sightings"] = int(sum(t[n][f"{m}_sightings"] for t in trials))
            cell[m]["wrong"] = int(sum(t[n][f"{m}_wrong"] for t in trials))
            cell[m]["below_ekf_every_axis"] = bool(
                np.all(np.array(cell[m]["mean_mm"]) < np.array(cell["ekf"]["mean_mm"]))
            )
        summary[str(n)] = cell
    summary["target_met"] = all(
        summary[str(n)][m]["below_ekf_every_axis"] for n in N_VALUES for m in ("batch", "online")
    )
    return summary


def plot(summary: dict, path: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    x = np.arange(len(N_VALUES))
    for i, (ax, name) in enumerate(zip(axes, AXES)):
        for j, m in enumerate(METHODS):
            mean = [summary[str(n)][m]["mean_mm"][i] for n in N_VALUES]
            std = [summary[str(n)][m]["std_mm"][i] for n in N_VALUES]
            ax.bar(x + (j - 1) * 0.27, mean, 0.27, yerr=std, label=m, capsize=2)
        ax.set_yscale("log")
        ax.set_xticks(x, [f"N={n}" for n in N_VALUES])
        ax.set_title(f"{name} error [mm]")
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--trials", type=int, default=SIZES["full"])
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--out", type=Path, default=Path("out/team_crawler"))
    p.add_argument("--doc", type=Path, help="also write the markdown here (docs/...)")
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args(argv)
    if args.trials < 1:
        p.error("--trials must be >= 1")
    args.out.mkdir(parents=True, exist_ok=True)
    with TrialExecutor(workers=args.workers, progress=not args.no_progress) as ex:
        trials = list(ex.imap(run_trial, list(range(args.trials)), desc="crawler-pair trials"))
    summary = summarize(trials)
    command = ".venv/bin/python scripts/bench_team_crawler.py" + (
        f" --trials {args.trials}" if args.trials != SIZES["full"] else ""
    )
    report = {"command": command, "trials": args.trials, "summary": summary}
    text = render("team_crawler", json.loads(dumps_json(report)))
    payload = {"summary": summary, "trials": trials}
    write_report(args.out, "team_crawler", payload, text, args.doc, rendered=report)
    plot(summary, args.out / "team_crawler.png")
    print(text)
    return 0
