"""Benchmark: the `dual-robot-room` scenario (seed 004, fa12d1d18dcbd0db.txt: a ground and a
ceiling robot scan one room; P3P of the ground robot's LEDs initializes ICP) through the front
door -- the log `graphloc simulate dual-robot-room` writes, read by `open_run`, its graph the
one `graphloc smooth` / `online` solve (`runner.team_run.team_graph`: the live builder's
KISS-ICP steps, LED candidate sets and causal inter-robot scan registration,
`live.event_scans`), solved by `graphloc.pipelines.team_graph.solve` -- beside the map-fusion
pipeline (`graphloc.pipelines.map_fusion.fuse`, what `graphloc fuse-maps` runs) on the same
simulated run.

Metric: the error of the ground -> ceiling transform at the first frame (rotation [deg],
translation [cm]); target (issue 14): within 0.1 deg / 1 cm in every variant.

    .venv/bin/python scripts/bench_team_dual_room.py --seeds 1 --out out/team_dual_room_quick
    .venv/bin/python scripts/bench_team_dual_room.py --out out/team_dual_room \\
        --doc docs/results_team_dual_room.md
"""

from __future__ import annotations

import argparse
import json
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from graphloc.datasets import open_run
from graphloc.datasets.dual_room import VARIANTS, DualRoomScenario, variant_config
from benchmarks.trials import TrialExecutor
from benchmarks.markdown import write_report
from benchmarks.render import render
from graphloc.pipelines.map_fusion.fusion import fuse
from graphloc.pipelines.map_fusion.options import FusionConfig
from graphloc.pipelines.map_fusion.types import FusionRejected
from graphloc.mapping.registration import pose_errors
from graphloc.pipelines.team_graph import GraphConfig, default_lag, solve
from graphloc.plots import plt
from graphloc.run import pose_from_xyz_quat
from graphloc.runner.team_run import team_graph
from graphloc.structured import dumps_json

METHODS = ("batch", "online", "fuse_maps")
TARGET = (0.1, 1.0)  # deg, cm
SIZES = {"full": 5, "quick": 1}  # seeds per variant


def _relative(rows_a: np.ndarray, rows_b: np.ndarray) -> np.ndarray:
    if not (np.isfinite(rows_a[0]).all() and np.isfinite(rows_b[0]).all()):
        return np.full((4, 4), np.nan)
    a, b = pose_from_xyz_quat(rows_a[0]), pose_from_xyz_quat(rows_b[0])
    return a.between(b).matrix()


def run_trial(item: tuple[str, int]) -> dict:
    """One simulated run of `variant` through the front door and through fuse()."""
    variant, seed = item
    scenario = DualRoomScenario.simulate(variant_config(variant, seed))
    truth = scenario.T_ground0_ceiling0
    out = {"variant": variant, "seed": seed}
    with tempfile.TemporaryDirectory() as tmp:
        scenario.write(Path(tmp))
        run = open_run(tmp)
        g, c = run.index("ground"), run.index("ceiling")
        graph = team_graph(run, GraphConfig())
        out["scan_matches"] = graph.counts.get("factors_scan_match", 0)
        out["skipped"] = graph.skips.as_dict()["counts"]
        for mode in ("batch", "online"):
            config = replace(graph.config, lag=default_lag(run, graph.config))
            result = solve(replace(graph, config=config), mode=mode)
            est = _relative(result.estimate[g], result.estimate[c])
            out[mode] = _errors(est, truth)
    try:
        fused = fuse(scenario.fusion_input(), FusionConfig(build_map=False))
        out["fuse_maps"] = _errors(fused.T_g0_c0, truth)
    except FusionRejected:
        out["fuse_maps"] = [float("nan"), float("nan")]
    return out


def _errors(est: np.ndarray, truth: np.ndarray) -> list:
    if not np.isfinite(est).all():
        return [float("nan"), float("nan")]
    rot, trans = pose_errors(est, truth)
    return [float(rot), float(100 * trans)]


def summarize(trials: list[dict]) -> dict:
    out = {}
    for v in VARIANTS:
        rows = [t for t in trials if t["variant"] == v]
        cell = {"runs": len(rows)}
        for m in METHODS:
            e = np.array([t[m] for t in rows], dtype=float).reshape(-1, 2)
            ok = np.isfinite(e).all(axis=1) & (e[:, 0] < TARGET[0]) & (e[:, 1] < TARGET[1])
            cell[m] = {
                "max_rot_deg": float(np.nanmax(e[:, 0])) if np.isfinite(e).any() else None,
                "max_trans_cm": float(np.nanmax(e[:, 1])) if np.isfinite(e).any() else None,
                "median_rot_deg": float(np.nanmedian(e[:, 0])) if np.isfinite(e).any() else None,
                "median_trans_cm": float(np.nanmedian(e[:, 1])) if np.isfinite(e).any() else None,
                "within_target": int(ok.sum()),
                "placed": int(np.isfinite(e).all(axis=1).sum()),
            }
        out[v] = cell
    out["target_met"] = all(
        out[v][m]["within_target"] == out[v]["runs"] for v in VARIANTS for m in ("batch", "online")
    )
    return out


def plot(trials: list[dict], path: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for j, (ax, unit) in enumerate(zip(axes, ("rotation error [deg]", "translation error [cm]"))):
        for i, m in enumerate(METHODS):
            for k, v in enumerate(VARIANTS):
                e = [t[m][j] for t in trials if t["variant"] == v]
                ax.scatter(np.full(len(e), k) + (i - 1) * 0.2, e, s=12, label=m if k == 0 else None)
        ax.axhline(TARGET[j], color="k", lw=0.8, ls="--")
        ax.set_xticks(range(len(VARIANTS)), VARIANTS, rotation=15)
        ax.set_yscale("log")
        ax.set_ylabel(unit)
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=SIZES["full"], help="seeds per variant")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--out", type=Path, default=Path("out/team_dual_room"))
    p.add_argument("--doc", type=Path, help="also write the markdown here (docs/...)")
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args(argv)
    if args.seeds < 1:
        p.error("--seeds must be >= 1")
    args.out.mkdir(parents=True, exist_ok=True)
    items = [(v, s) for v in VARIANTS for s in range(args.seeds)]
    with TrialExecutor(workers=args.workers, progress=not args.no_progress) as ex:
        trials = list(ex.imap(run_trial, items, desc="dual-robot-room runs"))
    summary = summarize(trials)
    command = ".venv/bin/python scripts/bench_team_dual_room.py" + (
        f" --seeds {args.seeds}" if args.seeds != SIZES["full"] else ""
    )
    report = {"command": command, "seeds": args.seeds, "summary": summary}
    text = render("team_dual_room", json.loads(dumps_json(report)))
    payload = {"summary": summary, "trials": trials}
    write_report(args.out, "team_dual_room", payload, text, args.doc, rendered=report)
    plot(trials, args.out / "team_dual_room.png")
    print(text)
    return 0
