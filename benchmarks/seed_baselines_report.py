"""Issue 20's job (scripts/bench_seed_baselines.py): the sweeps of
benchmarks.seed_baselines, then each table's graphloc run at the reading the sweep
chose (the reproducing setting) and at the setting the paper states, side by side with the
seed baseline; JSON, a PNG of the sweeps and docs/results_seed_baselines.md.

    .venv/bin/python scripts/bench_seed_baselines.py [--quick] [--workers 2] [--out DIR]
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from graphloc.datasets.feng_deterministic import TableIConfig
from graphloc.datasets.kaushik import KaushikConfig
from benchmarks import seed000, seed001_readings, seed003_readings, seed004
from benchmarks import seed_baselines_bounds_report, seed_baselines_bounds_t3
from benchmarks import seed_baselines_sections as sections
from benchmarks.render import render as render_doc
from benchmarks import seed_baselines as sb
from benchmarks.hypotheses import TableIIIConfig
from benchmarks.sizes import run_sizes
from graphloc.plots import plt
from graphloc.structured import dumps_json

SWEEP_SIZES = {
    False: {"t1_trials": 1000, "t3_runs": 12, "s4_runs": 150, "s4_frames": 4},
    True: {"t1_trials": 200, "t3_runs": 3, "s4_runs": 30, "s4_frames": 3},
}
# seed 001 experiment 1: rendered frames of runs 1 / 2; seed 003: sequences per schedule
MORE_SIZES = {
    False: {"s1_frames1": 300, "s1_frames2": 200, "s3_trials": 6},
    True: {"s1_frames1": 60, "s1_frames2": 40, "s3_trials": 1},
}
MORE = ("seed001", "seed003")
PARTS = MORE + ("bounds",)  # --only: "bounds" = seed 000's bounds (seed_baselines_bounds)
DOC = Path(__file__).resolve().parents[1] / "docs" / "results_seed_baselines.md"
DOC_JSON = DOC.with_suffix(".json")  # the last run's result: --only merges into it
MORE_PNG = "results_seed_baselines_001_003.png"


def _sizes(quick: bool):
    # Table III: 50 runs per cell (the paper: 100) keeps the job under ~15 min on 2 cores
    return replace(run_sizes(quick), table3_runs=min(run_sizes(quick).table3_runs, 50))


def _configs(sweeps: dict, setting: str, quick: bool, workers: int) -> dict:
    """The three tables' configs at the stated setting or at the sweeps' chosen readings."""
    sizes = _sizes(quick)
    if setting == "stated":
        return {
            "table1": TableIConfig(trials=sizes.table1_trials, workers=workers),
            "table3": TableIIIConfig(runs=sizes.table3_runs, workers=workers),
            "seed004": KaushikConfig(),
        }
    best = {k: sweeps[k]["choice"]["best"] for k in ("table1", "table3", "seed004")}
    return {
        "table1": sb.table1_config(best["table1"], sizes.table1_trials, workers),
        "table3": sb.table3_config(best["table3"], sizes.table3_runs, workers),
        "seed004": sb.seed004_config(best["seed004"]),
    }


def _table_run(table: str, config, quick: bool, workers: int, progress: bool) -> dict:
    if table == "table1":
        return seed000.table_i(config, progress)
    if table == "table3":
        return seed000.table_iii(config, progress)
    sizes = _sizes(quick)
    return seed004.seed004_table_1(
        runs=sizes.seed004_runs,
        frames=sizes.seed004_frames,
        workers=workers,
        progress=progress,
        base=config,
    )


def graphloc_runs(sweeps: dict, quick: bool, workers: int, progress: bool = True) -> dict:
    """Each table's full reproduction (seed baseline + graphloc, benchmarks.seed000
    / seed004) at the stated setting and at the chosen reading."""
    out = {}
    for setting in ("stated", "reproducing"):
        configs = _configs(sweeps, setting, quick, workers)
        out[setting] = {t: _table_run(t, c, quick, workers, progress) for t, c in configs.items()}
        out[setting]["configs"] = {t: asdict(c) for t, c in configs.items()}
    return out


def refresh(result: dict, workers: int, progress: bool = True) -> list:
    """A saved result re-chosen by today's `choose` (same sweep rows): the tables whose chosen
    reading changed get their reproducing run again. Returns their names."""
    changed = []
    for table in ("table1", "table3", "seed004"):
        choice = asdict(sb.choose(result["sweeps"][table]["rows"]))
        if choice != result["sweeps"][table]["choice"]:
            result["sweeps"][table]["choice"] = choice
            changed.append(table)
    for table in changed:
        config = _configs(result["sweeps"], "reproducing", result["quick"], workers)[table]
        rep = result["runs"]["reproducing"]
        rep[table] = _table_run(table, config, result["quick"], workers, progress)
        rep["configs"][table] = asdict(config)
    return changed


def rerun(result: dict, table: str, workers: int, progress: bool = True) -> None:
    """Both settings' runs of `table` again on the saved sweeps (the readings stay): for when
    a method of the table changed, not the reading."""
    for setting in ("stated", "reproducing"):
        config = _configs(result["sweeps"], setting, result["quick"], workers)[table]
        runs = result["runs"][setting]
        runs[table] = _table_run(table, config, result["quick"], workers, progress)
        runs["configs"][table] = asdict(config)


def plot(r: dict, path: Path) -> None:
    """Three panels: each sweep's largest deviation from the paper per reading."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    ax = axes[0]
    rows = r["sweeps"]["table1"]["rows"]
    for lat in sb.T1_LATERAL_SIGMAS:
        for orient, style in zip(sb.T1_ORIENTATIONS, ("-", ":")):
            sel = sorted(
                (x for x in rows if x["lateral_sigma"] == lat and x["orientation"] == orient),
                key=lambda x: x["pixel_sigma"],
            )
            ax.plot(
                [x["pixel_sigma"] for x in sel],
                [min(x["max_deviation"], 1e3) for x in sel],
                style,
                marker="o",
                ms=3,
                label=f"lateral {lat:g} m, {orient}",
            )
    ax.set(xscale="log", yscale="log", xlabel="image noise std [px]")
    ax.set_ylabel("largest |ours / paper - 1|")
    ax.set_title("Seed 000 Table I (seed baseline)", fontsize=10)
    ax.legend(fontsize=6)
    ax = axes[1]
    rows = r["sweeps"]["table3"]["rows"]
    for lik, frame in itertools.product(sb.T3_LIKELIHOODS, sb.T3_ACTION_FRAMES):
        for model, style in zip(sb.T3_ODOMETRY, ("-", ":")):
            sel = sorted(
                (
                    x
                    for x in rows
                    if (x["likelihood"], x.get("action_frame", "solution"), x["odometry_model"])
                    == (lik, frame, model)
                ),
                key=lambda x: x["pixel_sigma"],
            )
            if not sel:
                continue
            ax.plot(
                [x["pixel_sigma"] for x in sel],
                [min(x["max_deviation"], 1e3) for x in sel],
                style,
                marker="o",
                ms=3,
                label=f"{lik}, {frame}, {model}",
            )
    ax.set(xscale="log", yscale="log", xlabel="image noise std [px]")
    ax.set_title("Seed 000 Table III (belief vector)", fontsize=10)
    ax.legend(fontsize=6)
    ax = axes[2]
    rows = [x for x in r["sweeps"]["seed004"]["rows"] if x["cells"] is not None]
    for noise, marker in zip(sb.S4_NOISE_READINGS, ("o", "x")):
        for off in sb.S4_OFFSETS:
            sel = [x for x in rows if x["noise_reading"] == noise and x["offset"] == off]
            ax.scatter(
                [x["height"] ** 2 * x["pitch_um"] for x in sel],
                [x["max_deviation"] for x in sel],
                s=12,
                marker=marker,
                label=f"offset {off:g} m, sigma^2 read as {noise}",
            )
    ax.axhline(sb.REPRODUCE_TOL, color="k", lw=0.8, ls="--")
    ax.set(yscale="log", xlabel="height^2 x pixel pitch [m^2 um]")
    ax.set_title("Seed 004 Table 1 (raw P3P)", fontsize=10)
    ax.legend(fontsize=5, ncol=2)
    for a, ticks in zip(axes[:2], (sb.T1_PIXEL_SIGMAS, sb.T3_PIXEL_SIGMAS)):
        a.axhline(sb.REPRODUCE_TOL, color="k", lw=0.8, ls="--")
        a.set_xticks(sorted(ticks), [f"{t:g}" for t in sorted(ticks)], minor=False, fontsize=7)
        a.minorticks_off()
    fig.suptitle("Readings of the seeds' setups: largest deviation from the paper (dashed: 10 %)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(out: Path, quick: bool, workers: int, docs: bool = True, progress: bool = True) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    sweeps = sb.sweep_all(SWEEP_SIZES[quick], workers, progress)
    result = {"quick": quick, "workers": workers, "sweeps": sweeps}
    result["runs"] = graphloc_runs(sweeps, quick, workers, progress)
    result["wall_time_s"] = time.perf_counter() - t0
    run_more(result, PARTS, quick, workers, progress)
    (out / "seed_baselines.json").write_text(dumps_json(result, indent=1, default=_json))
    return render(result, out, docs)


def run_more(result: dict, parts, quick: bool, workers: int, progress: bool = True) -> dict:
    """Seed 001 experiment 1 and / or seed 003 Fig. 6 (`parts`), each with its sweep, choice
    and both methods at the stated and the chosen reading, and / or seed 000's bounds
    ("bounds", at the sweeps' sizes), into `result` (the seed 000 / 004 sweeps and runs
    untouched); the wall times of seed 001 / 003 under result["more_wall_time_s"]."""
    sizes = MORE_SIZES[quick]
    times = result.setdefault("more_wall_time_s", {})
    for part in parts:
        t0 = time.perf_counter()
        if part == "bounds":
            result[part] = seed_baselines_bounds_t3.bounds(SWEEP_SIZES[quick], workers, progress)
            continue
        if part == "seed001":
            result[part] = seed001_readings.run_all(
                sizes["s1_frames1"], sizes["s1_frames2"], sb.choose, progress=progress
            )
        else:
            result[part] = seed003_readings.run_all(sizes["s3_trials"], workers, progress=progress)
        result[part]["quick"] = quick
        times[part] = time.perf_counter() - t0
    return result


def render(result: dict, out: Path, docs: bool = True) -> dict:
    """Plot and markdown of a result (also from its saved JSON: --render)."""
    out.mkdir(parents=True, exist_ok=True)
    plot(result, out / "results_seed_baselines.png")
    more = any(k in result for k in MORE)
    if more:
        sections.plot(result, out / MORE_PNG)
    if "bounds" in result:
        seed_baselines_bounds_report.plot(result["bounds"], out)
    # rendered from the JSON as written (numpy values as plain numbers), as the committed doc is
    md = render_doc("seed_baselines", json.loads(dumps_json(result, default=_json)))
    (out / "seed_baselines.md").write_text(md)
    if docs:
        plot(result, DOC.with_suffix(".png"))
        if more:
            sections.plot(result, DOC.parent / MORE_PNG)
        if "bounds" in result:
            seed_baselines_bounds_report.plot(result["bounds"], DOC.parent)
        DOC_JSON.write_text(dumps_json(result, separators=(",", ":"), default=_json))
        DOC.write_text(md)
    result["markdown"] = md
    return result


def _json(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="CI size")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("out/seed_baselines"))
    parser.add_argument("--no-docs", action="store_true", help="do not write docs/")
    parser.add_argument(
        "--render",
        type=Path,
        help="redraw plot and markdown from this run's JSON (re-running a table only when "
        "its chosen reading changed)",
    )
    parser.add_argument(
        "--resweep", choices=["table3"], help="with --render: redo the Table III sweep only"
    )
    parser.add_argument(
        "--rerun",
        choices=["table1", "table3", "seed004"],
        action="append",
        default=[],
        help="with --render: run this table's methods again at both settings (a method "
        "changed; the sweep and its chosen reading stay)",
    )
    parser.add_argument(
        "--only",
        help="comma list of seed001,seed003,bounds (seed 000's bounds): run only these parts "
        "and merge them into the previous result (--previous), leaving its seed 000 / 004 "
        "sweeps and runs as they are",
    )
    parser.add_argument("--previous", type=Path, default=DOC_JSON, help="with --only")
    args = parser.parse_args(argv)
    if args.only:
        parts = [p.strip() for p in args.only.split(",") if p.strip()]
        bad = [p for p in parts if p not in PARTS]
        if bad or not parts:
            parser.error(f"--only: {bad or args.only!r} not among {', '.join(PARTS)}")
        if not args.previous.is_file():
            parser.error(f"--only merges into a previous result; {args.previous} does not exist")
        r = json.loads(args.previous.read_text())
        run_more(r, parts, args.quick, args.workers)
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "seed_baselines.json").write_text(dumps_json(r, indent=1, default=_json))
        r = render(r, args.out, docs=not args.no_docs)
    elif args.render:
        r = json.loads(args.render.read_text())
        if args.resweep == "table3":  # only this sweep's rows recomputed
            rows = sb.table3_sweep(SWEEP_SIZES[r["quick"]]["t3_runs"], args.workers)
            r["sweeps"]["table3"]["rows"] = rows
        for table in args.rerun:
            rerun(r, table, args.workers)
        if refresh(r, args.workers) or args.resweep or args.rerun:
            (args.out / "seed_baselines.json").write_text(dumps_json(r, indent=1, default=_json))
        r = render(r, args.out, docs=not args.no_docs)
    else:
        r = run(args.out, args.quick, args.workers, docs=not args.no_docs)
    print(r["markdown"])
    return 0
