"""Be graphloc's new user: generate runs, feed them to its command line, judge the answers.

For each case (layout, seed, corruption) this writes the run with ``team_generator``, runs
``graphloc validate RUN``, ``graphloc smooth RUN --out ...`` and ``graphloc online RUN
--out ...`` as subprocesses (the CLI only, no graphloc import), keeps their terminal output, reads
``metrics.json`` (skips, decisions, down-weighted factors) and scores the TUM estimates against
the ground truth in the world frame (``score``). A case is **confidently wrong** when the verb
exited 0, printed no warning or ``inconsistent:`` line, its metrics.json did not say
``"consistent": false``, and some robot's final or RMS position error exceeds ``--bar`` (0.3 m),
or a robot of the run has no estimate.

``python tests/foreign/run_matrix.py --out DIR [--graphloc .venv/bin/graphloc] [--seeds 0 1 2]``
writes ``DIR/results.json`` and ``DIR/results.md`` (runs in ``DIR/runs``, outputs in
``DIR/out``, terminal output in ``DIR/logs``). Cases run one after another (the machine is
shared).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import score as scoring  # noqa: E402
import team_generator as gen  # noqa: E402

#: the layouts each corruption is tried on (seed 0), with a run length [s] (None: default)
CORRUPTION_CASES = {
    "swap-uv": [("ceiling-markers", None), ("mixed-team", None)],
    "wrong-intrinsics": [("ceiling-markers", None), ("mixed-team", None)],
    "wrong-layout": [("ceiling-markers", None)],
    "wrong-layout-scale": [("ceiling-markers", None)],
    "odometry-x2": [("ceiling-markers", None), ("wall-bearings", 60.0)],
    "target-typo": [("ceiling-markers", None), ("wall-bearings", 60.0)],
}

WARNING = re.compile(r"warn|inconsistent:", re.IGNORECASE)
PY_WARNING = re.compile(r"\b\w+Warning:|warnings\.warn|^\s+\S.*$")


#: runs that differ from a clean one in one reading of the doc (name, layout, seed, options)
VARIANT_CASES = [
    ("camera-offset", "ceiling-markers", 0, {"camera_offset_s": 0.1}),
    ("extrinsics-matrix", "ceiling-markers", 0, {"extrinsics_form": "matrix"}),
    ("landmarks-at-sensor-height", "mixed-team", 2, {"landmark_heights": "sensor"}),
    ("landmark-sensor-offset", "mixed-team", 0, {"landmark_sensor_offset": True}),
]


def plan(seeds, layouts, corruptions, variants=False) -> list[dict]:
    cases = []
    for layout in layouts:
        for seed in seeds:
            cases.append({"layout": layout, "seed": seed, "corrupt": None, "duration": None})
    for kind in corruptions:
        for layout, duration in CORRUPTION_CASES[kind]:
            if layout in layouts:
                cases.append({"layout": layout, "seed": 0, "corrupt": kind, "duration": duration})
    if variants:
        for name, layout, seed, options in VARIANT_CASES:
            if layout in layouts:
                cases.append({"layout": layout, "seed": seed, "corrupt": None, "duration": None,
                              "variant": name, "options": options})  # fmt: skip
    return cases


def case_id(case: dict) -> str:
    name = f"{case['layout']}-s{case['seed']}"
    if case["corrupt"]:
        name += f"-{case['corrupt']}"
    if case["duration"]:
        name += f"-{int(case['duration'])}s"
    if case.get("variant"):
        name += f"-{case['variant']}"
    return name


def split_warnings(text: str) -> tuple[list[str], list[str]]:
    """(graphloc's warning lines, Python warnings leaked to the terminal)."""
    ours, python = [], []
    for line in text.splitlines():
        if not WARNING.search(line):
            continue
        if re.search(r"\b[A-Z]\w*Warning:", line):
            python.append(line.strip())
        else:
            ours.append(line.strip())
    return ours, python


def run_verb(graphloc: str, verb: str, run_dir: Path, out_dir: Path | None, log_dir: Path,
             name: str, timeout: float) -> dict:  # fmt: skip
    cmd = [graphloc, verb, str(run_dir)]
    if out_dir is not None:
        cmd += ["--out", str(out_dir), "--no-progress"]
    start = time.monotonic()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        rc, stdout, stderr = proc.returncode, proc.stdout, proc.stderr
    except subprocess.TimeoutExpired as exc:
        rc, stdout, stderr = "timeout", exc.stdout or "", exc.stderr or ""
        stdout = stdout.decode() if isinstance(stdout, bytes) else stdout
        stderr = stderr.decode() if isinstance(stderr, bytes) else stderr
    wall = time.monotonic() - start
    (log_dir / f"{name}.{verb}.out").write_text(stdout)
    (log_dir / f"{name}.{verb}.err").write_text(stderr)
    ours, python = split_warnings(stdout + "\n" + stderr)
    errors = [line for line in stderr.splitlines() if "error:" in line]
    return {"cmd": " ".join(cmd), "rc": rc, "wall_s": round(wall, 1), "warnings": ours,
            "python_warnings": sorted(set(python)), "errors": errors, "stdout": stdout}  # fmt: skip


def metrics_summary(out_dir: Path) -> dict:
    path = out_dir / "metrics.json"
    if not path.exists():
        return {}
    m = json.loads(path.read_text())
    dec = m.get("decisions") or {}
    return {
        "skipped": (m.get("skipped") or {}).get("counts", {}),
        "decided": dec.get("committed"),
        "candidate_sets": dec.get("candidate_sets"),
        "wrong_by_graphloc": dec.get("wrong"),
        "downweighted": {
            k: f"{v.get('downweighted')}/{v.get('robust_factors')}"
            for k, v in (m.get("downweighted") or {}).items()
        },  # fmt: skip
        "partial": m.get("partial"),
        "batch_start": m.get("batch_start"),
        "lag_s": m.get("lag_s"),
        "solve_wall_s": m.get("solve_wall_s"),
        "realtime_factor": m.get("realtime_factor"),
        "consistent": m.get("consistent"),
    }


def judge(verb: dict, scores: dict | None, bar: float) -> str:
    """``yes`` (exit 0, no warning, not called inconsistent, a robot off by more than ``bar``),
    ``unplaced`` (the same, a robot of the run without an estimate) or ``no``."""
    said_so = verb["warnings"] or (verb.get("metrics") or {}).get("consistent") is False
    if verb["rc"] != 0 or said_so or scores is None:
        return "no"
    off = any(
        r["final_m"] > bar or r["rmse_m"] > bar
        for r in scores["robots"].values()
        if not r.get("unplaced")
    )
    if off:
        return "yes"
    return "unplaced" if scores["unplaced"] else "no"


def run_case(case: dict, root: Path, graphloc: str, bar: float, timeout: float) -> dict:
    name = case_id(case)
    run_dir = root / "runs" / name
    log_dir = root / "logs"
    log_dir.mkdir(parents=True, exist_ok=True)
    if not (run_dir / "manifest.json").exists():
        config = gen.GeneratorConfig(
            layout=case["layout"],
            seed=case["seed"],
            corrupt=case["corrupt"],
            duration_s=case["duration"],
            **case.get("options", {}),
        )
        gen.generate(run_dir, config)
    result = {"case": name, **case}
    validate = run_verb(graphloc, "validate", run_dir, None, log_dir, name, timeout)
    try:
        report = json.loads(validate["stdout"])
        validate["skipped"] = report.get("skipped", {}).get("counts", {})
    except json.JSONDecodeError:
        validate["skipped"] = None
    validate.pop("stdout")
    result["validate"] = validate
    for verb, mode in (("smooth", "batch"), ("online", "online")):
        out_dir = root / "out" / name / mode
        if out_dir.exists() and (out_dir / "metrics.json").exists():
            out_dir = root / "out" / name / f"{mode}-{int(time.time())}"
        r = run_verb(graphloc, verb, run_dir, out_dir, log_dir, name, timeout)
        r.pop("stdout")
        r["metrics"] = metrics_summary(out_dir)
        scores = scoring.score(run_dir, out_dir, mode) if r["metrics"] else None
        r["scores"] = scores
        r["confidently_wrong"] = judge(r, scores, bar)
        result[mode] = r
        print(
            f"{name} {verb}: rc={r['rc']} {r['wall_s']} s worst_final="
            f"{scores and scores['worst_final_m']} cw={r['confidently_wrong']}",
            flush=True,
        )
    return result


def _robots_cell(scores: dict | None) -> str:
    if not scores:
        return "-"
    parts = []
    for name, r in scores["robots"].items():
        if r.get("unplaced"):
            parts.append(f"{name}: unplaced")
        else:
            parts.append(f"{name} {r['final_m']:.2f}/{r['max_m']:.2f}")
    return "<br>".join(parts)


def _verdict(value, scores: dict) -> str:
    if value in (True, "yes"):
        return "**yes**"
    if value == "unplaced":
        return f"**silent: {', '.join(scores['unplaced'])} unplaced**"
    return "no"


def markdown(results: list[dict], bar: float) -> str:
    lines = [
        "| case | verb | exit | wall s | robot final/max [m] | skips | decided (graphloc wrong"
        " / truth wrong) | down-weighted | warnings | confidently wrong |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for res in results:
        for mode in ("batch", "online"):
            r = res.get(mode)
            if r is None:
                continue
            m = r["metrics"]
            s = r["scores"] or {}
            d = s.get("decisions", {})
            dec = (f"{m.get('decided')}/{m.get('candidate_sets')} ({m.get('wrong_by_graphloc')}"
                   f" / {d.get('wrong_by_truth')})") if m else "-"  # fmt: skip
            skips = ", ".join(f"{k} {v}" for k, v in (m.get("skipped") or {}).items()) or "0"
            warn = "; ".join(r["warnings"] + r["errors"])[:200] or "none"
            lines.append(
                f"| {res['case']} | {mode} | {r['rc']} | {r['wall_s']} | {_robots_cell(s)} | "
                f"{skips if m else '-'} | {dec} | "
                f"{', '.join(f'{k} {v}' for k, v in (m.get('downweighted') or {}).items()) or '-'}"
                f" | {warn} | {_verdict(r['confidently_wrong'], s)} |"
            )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--graphloc", default=".venv/bin/graphloc")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--layouts", nargs="+", choices=gen.LAYOUTS, default=list(gen.LAYOUTS))
    parser.add_argument("--corruptions", nargs="*", choices=gen.CORRUPTIONS,
                        default=list(gen.CORRUPTIONS))  # fmt: skip
    parser.add_argument("--bar", type=float, default=0.3, help="position error bar [m]")
    parser.add_argument("--timeout", type=float, default=3600.0, help="per verb [s]")
    parser.add_argument(
        "--variants",
        action="store_true",
        help="also the runs of VARIANT_CASES (other readings of the doc)",
    )
    parser.add_argument(
        "--render",
        action="store_true",
        help="only re-judge DIR/results.json and rewrite DIR/results.md",
    )
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    results_path = args.out / "results.json"
    results = json.loads(results_path.read_text()) if results_path.exists() else []
    if args.render:
        for res in results:
            for mode in ("batch", "online"):
                r = res.get(mode)
                if r is not None:
                    r["confidently_wrong"] = judge(r, r["scores"], args.bar)
        results_path.write_text(json.dumps(results, indent=1) + "\n")
        (args.out / "results.md").write_text(markdown(results, args.bar))
        return 0
    done = {r["case"] for r in results}
    for case in plan(args.seeds, args.layouts, args.corruptions, args.variants):
        if case_id(case) in done:
            continue
        results.append(run_case(case, args.out, args.graphloc, args.bar, args.timeout))
        results_path.write_text(json.dumps(results, indent=1) + "\n")
        (args.out / "results.md").write_text(markdown(results, args.bar))
    (args.out / "results.md").write_text(markdown(results, args.bar))
    return 0


if __name__ == "__main__":
    sys.exit(main())
