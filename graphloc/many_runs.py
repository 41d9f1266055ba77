"""`graphloc smooth` / `online` over many runs (several paths, a glob or `--runs FILE`): each run
one `Executor` task into DIR/<run name>/, cached by content hash, and the aggregate report
runs.csv, runs.md, runs.json, runs_summary.png (docs/outputs.md)."""

from __future__ import annotations

import argparse
import contextlib
import csv
import glob
import json
import sys
from pathlib import Path

from graphloc.executor import BACKENDS, Executor, ResultCache, content_hash
from graphloc.exitcodes import INCOMPLETE, OK, RUNS_FAILED
from graphloc.names import out_path
from graphloc.structured import dumps_json

# namespace fields that choose where / how runs execute, not what they compute
_NOT_CONFIG = {"run", "out", "config", "no_progress", "runs", "backend", "workers", "address"}
_NOT_CONFIG |= {"cache", "checkpoint", "checkpoint_every", "resume", "_run", "verb"}
_NOT_CONFIG |= {"verbose", "quiet"}  # graphloc.commands.common: how much is printed
MAX_WORKERS = 256  # parallel runs (processes or Ray tasks in flight)
_FIELDS = ["run", "status", "error", "seconds", "robots", "ate_rmse_m", "committed", "wrong"]
_FIELDS += ["realtime_factor", "path"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The many-run options of `smooth` / `online`."""
    parser.add_argument("--runs", type=Path, help="file with one run path per line (# comments)")
    parser.add_argument(
        "--backend", choices=BACKENDS, help="many runs: local process pool (default) or Ray"
    )
    parser.add_argument("--workers", type=int, default=1, help="many runs: parallel runs")
    parser.add_argument(
        "--address", help="--backend ray: 'auto' or HOST:PORT of an existing Ray cluster"
    )
    parser.add_argument("--cache", type=Path, help="many runs: result cache (default OUT/.cache)")


def expand_runs(patterns: list[str], runs_file: Path | None) -> list[Path]:
    """Run paths from the command line (a pattern that names nothing is globbed) and from the
    runs file (relative paths are relative to the file); ValueError names what matched
    nothing."""
    runs: list[Path] = []
    for text in patterns:
        if Path(text).exists() or not any(c in text for c in "*?["):
            runs.append(Path(text))
            continue
        found = sorted(glob.glob(text))
        if not found:
            raise ValueError(f"run pattern {text!r} matches nothing")
        runs += [Path(f) for f in found]
    if runs_file is not None:
        try:
            lines = runs_file.read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"--runs {runs_file}: cannot read: {exc}") from None
        for n, line in enumerate(lines, 1):
            text = line.split("#", 1)[0].strip()
            if not text:
                continue
            path = Path(text) if Path(text).is_absolute() else runs_file.parent / text
            if not path.exists():
                raise ValueError(f"{runs_file}, line {n}: run {text!r}: no such file or directory")
            runs.append(path)
    if not runs:
        raise ValueError("no runs given")
    return runs


def dispatch(args: argparse.Namespace, mode: str, verb, checkpoint=None) -> int:
    """One run without --runs / --backend: `verb(args, mode, checkpoint)`, the single-run
    verb as it is. Several runs (or a glob matching several, --runs, --backend): `run_many`."""
    workers = getattr(args, "workers", 1)
    if not (isinstance(workers, int) and 1 <= workers <= MAX_WORKERS):
        raise ValueError(f"--workers must be an integer in [1, {MAX_WORKERS}], got {workers}")
    patterns = args.run if isinstance(args.run, list) else [args.run]
    runs_file, backend = getattr(args, "runs", None), getattr(args, "backend", None)
    runs = None
    if len(patterns) == 1 and runs_file is None and backend is None:
        text = patterns[0]
        if Path(text).exists() or not any(c in text for c in "*?["):
            args.run = text  # a missing path is the verb's error, as for one run
            return verb(args, mode, checkpoint)
        runs = expand_runs(patterns, None)
        if len(runs) == 1:
            args.run = str(runs[0])
            return verb(args, mode, checkpoint)
    if checkpoint is not None:
        raise ValueError("--checkpoint / --resume take one run, not several")
    return run_many(args, mode, verb, runs or expand_runs(patterns, runs_file))


def _names(runs: list[Path]) -> list[str]:
    """Output folder per run: its name, made unique with -2, -3 ... ."""
    seen: dict[str, int] = {}
    names = []
    for path in runs:
        base = path.resolve().name or "run"
        seen[base] = seen.get(base, 0) + 1
        names.append(base if seen[base] == 1 else f"{base}-{seen[base]}")
    return names


def _solve_one(item: tuple) -> dict:
    """Task: one run through the verb, its printed summary in OUT/log.txt; the row of the
    aggregate report from its metrics.json."""
    verb, fields, mode = item
    args = argparse.Namespace(**fields)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "log.txt", "w") as log, contextlib.redirect_stdout(log):
        code = verb(args, mode, None)
    metrics = json.loads((out / "metrics.json").read_text())
    return {
        "status": "partial" if code == INCOMPLETE else "ok",
        "robots": len(metrics["per_robot"]),
        "ate_rmse_m": ate_by_robot(metrics, mode),
        "committed": metrics["decisions"]["committed"],
        "wrong": metrics["decisions"]["wrong"],
        "realtime_factor": round(metrics["realtime_factor"], 2),
    }


def ate_by_robot(metrics: dict, mode: str) -> dict:
    """Robot -> the estimate's ATE RMSE [m] in a run's metrics (robots without one left out)."""
    return {
        name: v[mode]["ate_rmse"]
        for name, v in metrics["per_robot"].items()
        if isinstance(v.get(mode), dict) and "ate_rmse" in v[mode]
    }


def run_many(args: argparse.Namespace, mode: str, verb, runs: list[Path]) -> int:
    """Every run as one executor task; the aggregate report; the exit code."""
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out}: exists and is not a directory")
    names = _names(runs)
    fields = {k: v for k, v in vars(args).items() if not callable(v)}
    config = {k: v for k, v in sorted(fields.items()) if k not in _NOT_CONFIG}
    config["mode"] = mode
    extra = [args.config] if args.config is not None else []
    items, hashes = [], []
    for path, name in zip(runs, names):
        run_out = out_path(out, name)
        run_fields = dict(fields, run=str(path), out=run_out, no_progress=True)
        for key in ("mcap", "rerun"):  # a recording per run, in its own folder
            if fields.get(key):
                run_fields[key] = str(out_path(run_out, Path(fields[key]).name))
        items.append((verb, run_fields, mode))
        try:
            hashes.append(content_hash([path, *extra], config))
        except FileNotFoundError:  # reported by the task as that run's error
            hashes.append(f"missing-{name}")
    cache = ResultCache(args.cache if args.cache is not None else out / ".cache")
    for h, name in zip(hashes, names):  # a cached run counts only while its outputs exist
        if not (out / name / "metrics.json").exists():
            cache.discard(h)
    backend = args.backend or "local"
    with Executor(args.workers, backend, args.address, progress=not args.no_progress) as ex:
        outcomes = ex.map(
            _solve_one, items, keys=names, cache=cache, hashes=hashes, desc=f"{mode} runs"
        )
    rows = []
    for path, o in zip(runs, outcomes):
        row = {"run": o.key, "path": str(path), "seconds": round(o.seconds, 3)}
        if o.ok:
            row.update(o.value)
            row["status"] = "cached" if o.cached else o.value["status"]
        else:
            row.update(status="failed", error=o.error)
        rows.append(row)
    write_report(rows, out, mode)
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", "cached", "partial", "failed")}
    for r in rows:
        if r["status"] == "failed":
            print(f"graphloc: run {r['path']} failed: {r['error']}", file=sys.stderr)
    print(dumps_json({"mode": mode, "backend": backend, "runs": len(rows), **counts}))
    print(f"outputs in {out} (runs.csv, runs.md, runs_summary.png)")
    if counts["failed"]:
        return RUNS_FAILED
    return INCOMPLETE if counts["partial"] else OK


def _cells(row: dict) -> list:
    ate = row.get("ate_rmse_m") or {}
    text = " ".join(f"{k}={v:.4f}" for k, v in ate.items())
    return [row.get(f) if f != "ate_rmse_m" else text for f in _FIELDS]


def write_report(rows: list[dict], out: Path, mode: str) -> None:
    """runs.csv, runs.md, runs.json and runs_summary.png under `out`."""
    import numpy as np

    from graphloc.plots import plt

    out.mkdir(parents=True, exist_ok=True)
    (out / "runs.json").write_text(dumps_json({"mode": mode, "runs": rows}, indent=1))
    with open(out / "runs.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(_FIELDS)
        w.writerows(_cells(r) for r in rows)
    md = [f"# graphloc {mode}: {len(rows)} runs", "", "| " + " | ".join(_FIELDS) + " |"]
    md.append("|" + "---|" * len(_FIELDS))
    for r in rows:
        md.append("| " + " | ".join("" if c is None else str(c) for c in _cells(r)) + " |")
    (out / "runs.md").write_text("\n".join(md) + "\n")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 0.35 * len(rows) + 2))
    y = np.arange(len(rows))
    mean_ate = [np.mean(list(r["ate_rmse_m"].values())) if r.get("ate_rmse_m") else 0 for r in rows]
    colors = [
        {"failed": "tab:red", "cached": "tab:gray"}.get(r["status"], "tab:blue") for r in rows
    ]
    a1.barh(y, mean_ate, color=colors)
    a1.set_xlabel(f"{mode} ATE RMSE, mean over robots [m]")
    a2.barh(y, [r["seconds"] for r in rows], color=colors)
    a2.set_xlabel("task wall time [s] (0: cached)")
    for ax in (a1, a2):
        ax.set_yticks(y, [f"{r['run']} ({r['status']})" for r in rows], fontsize=7)
        ax.invert_yaxis()
    fig.tight_layout()
    fig.savefig(out / "runs_summary.png", dpi=110)
    plt.close(fig)
