"""`graphloc smooth FILE` / `online FILE` for a pose-graph file with discrete alternatives
(City10000, g2o), solved step by step by `PoseGraphHypotheses` then refined
(`--candidate-seed`, `--null-loops`, `--truth-poses`; outputs in docs/outputs.md)."""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import numpy as np

from graphloc.commands.common import verdict_exit
from graphloc.exitcodes import SolverFailure
from graphloc.textio import check_file, shown, text_lines

SIGMAS = {2: (0.05, 0.05, 0.01), 3: (0.01, 0.01, 0.01, 0.05, 0.05, 0.05)}  # no information


def is_pose_graph_file(path) -> bool:
    """A regular file whose first data line starts with a tag the pose-graph reader reads."""
    from graphloc.datasets.pose_graph_file import TAGS

    path = Path(str(path))
    if not path.is_file():
        return False
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096).decode("utf-8", "replace").lstrip("\ufeff")
    except OSError:
        return False
    for line in head.splitlines():
        parts = line.split()
        if parts and not parts[0].startswith("#"):
            return parts[0] in TAGS
    return False


def reject_options(given: dict, path) -> None:
    """ValueError when pose-graph options meet another kind of run."""
    if given:
        flags = ", ".join("--" + k.replace("_", "-") for k in sorted(given))
        raise ValueError(f"{path}: {flags} applies to a pose-graph file (City10000 / g2o) only")


def read_truth(path, dim: int) -> np.ndarray:
    """Ground-truth poses, one line per pose id: (n, 3) x y theta or (n, 7) x y z qx qy qz qw;
    ValueError naming file, line and field."""
    path = Path(path)
    check_file(path, what="truth-poses file")
    width, rows = (3 if dim == 2 else 7), []
    for line_no, text in text_lines(path):
        parts = text.split()
        if not parts or parts[0].startswith("#"):
            continue
        if len(parts) != width:
            raise ValueError(f"{path}: line {line_no}: expected {width} fields, got {len(parts)}")
        try:
            row = [float(p) for p in parts]
        except ValueError:
            raise ValueError(f"{path}: line {line_no}: {shown(text)} is not numbers") from None
        bad = [k for k, v in enumerate(row) if not np.isfinite(v)]
        if bad:
            raise ValueError(f"{path}: line {line_no}: field {bad[0] + 1} is not finite")
        rows.append(row)
    if not rows:
        raise ValueError(f"{path}: no pose")
    return np.array(rows)


def read_file(path, options: dict):
    """The pose-graph file (malformed lines counted and skipped, `--null-loops` applied)."""
    from graphloc.datasets.pose_graph_file import read_pose_graph

    return read_pose_graph(path, on_error="skip", null_on_loops=bool(options.get("null_loops")))


def summary(graph) -> dict:
    """What `graphloc validate` says of a pose-graph file: measurements by kind, vertices, skipped
    lines, and the first edge that does not grow the graph from its first pose."""
    from collections import Counter

    from graphloc.datasets.pose_graph_file import group_steps

    ms = graph.measurements
    sizes = Counter(len(m.candidates) for m in ms)
    steps = group_steps(ms)
    known, unreachable, first_bad = {steps[0][0][1].source}, 0, None
    for step in steps:
        for _, m in step:
            if m.source not in known:
                unreachable += 1
                first_bad = first_bad or (
                    f"line {m.line}: {m.source} -> {m.target}: {m.source} is no pose of the "
                    "edges before it (edges must grow the graph from its first pose)"
                )
            known.add(m.target)
    return {
        "path": str(graph.path), "format": graph.format, "dim": graph.dim,
        "vertices": len(graph.vertices),
        "poses": len({k for m in ms for k in (m.source, m.target)}),
        "measurements": {
            "total": len(ms),
            "certain": sum(not m.ambiguous for m in ms),
            "with_candidates": sum(len(m.candidates) > 1 for m in ms),
            "with_null": sum(bool(m.null) for m in ms),
            "loop_closures": sum(abs(m.target - m.source) != 1 for m in ms),
            "candidates_per_measurement": dict(sorted(sizes.items())),
        },
        "steps": len(steps),
        "unreachable_edges": unreachable,
        **({"first_unreachable": first_bad} if first_bad else {}),
        "skipped": graph.skips.as_dict(),
    }  # fmt: skip


def solve_file(graph, mode: str, options: dict, stop=None, progress: bool = False) -> dict:
    """Solve step by step, (batch) refine: the estimate and what metrics.json reports."""
    import gtsam
    from gtsam.symbol_shorthand import X
    from tqdm import tqdm

    from graphloc.datasets.pose_graph_file import group_steps, permute_candidates
    from graphloc.hypotheses.pose_graph import PoseGraphConfig, PoseGraphHypotheses

    cpu0 = time.process_time()
    truth = {}
    measurements = graph.measurements
    if options.get("candidate_seed") is not None:
        measurements, truth = permute_candidates(measurements, options["candidate_seed"])
    steps = group_steps(measurements)
    engine = PoseGraphHypotheses(graph.dim, PoseGraphConfig(sigmas=SIGMAS[graph.dim]))
    first = steps[0][0][1].source
    engine.start(first, graph.vertices.get(first))
    latency, causal, partial = [], [], False
    for step in tqdm(steps, disable=not progress, desc="pose graph", leave=False):
        if stop is not None and stop():
            partial = True
            break
        start = time.process_time()
        try:
            engine.step(step)
        except SolverFailure:
            raise
        except ValueError as exc:  # an edge that does not grow the graph: name the file
            raise ValueError(f"{graph.path}: {exc}") from None
        if mode == "online":
            node = max(max(m.source, m.target) for _, m in step)
            causal.append((node, _row(engine.current(node), graph.dim)))
        latency.append(time.process_time() - start)
    estimate = engine.finish()  # LM on the decided graph, nulls decided again at its optimum
    nodes = sorted(int(gtsam.Symbol(k).index()) for k in estimate.keys())
    poses = np.array([_row(_get(estimate, X(n), graph.dim), graph.dim) for n in nodes])
    choices = engine.choices()
    factors = factor_statistics(engine.final_graph, estimate)
    return {
        "graph": graph, "measurements": measurements, "truth": truth, "choices": choices,
        "nodes": nodes, "poses": poses, "latency": latency, "causal": causal, "partial": partial,
        "cpu": time.process_time() - cpu0, "stats": dict(engine.stats),
        "undecided": engine.undecided_count(), "factors": factors,
    }  # fmt: skip


def factor_statistics(graph, estimate) -> dict:
    """Per factor kind (`prior`, `odometry`, `loop_closure`): count, residual dimension, chi-square
    and normalized chi-square (chi2 / dim)."""
    from gtsam import Symbol

    out: dict = {}
    for i in range(graph.size()):
        f = graph.at(i)
        if f is None:  # a slot a re-decision emptied
            continue
        keys = [Symbol(k).index() for k in f.keys()]
        kind = (
            "prior"
            if len(keys) == 1
            else "odometry"
            if abs(keys[1] - keys[0]) == 1
            else "loop_closure"
        )
        row = out.setdefault(kind, {"count": 0, "dim": 0, "chi2": 0.0})
        row["count"] += 1
        row["dim"] += int(f.dim())
        row["chi2"] += 2.0 * f.error(estimate)
    for row in out.values():
        row["normalized_chi2"] = row["chi2"] / row["dim"] if row["dim"] else None
    return out


def verdict(metrics: dict) -> dict:
    """The consistency verdict of a pose-graph solve (as `team_graph.verdict`): every factor kind's
    normalized chi-square at most `max_normalized_chi2`, at most `max_null_share` of the
    null-component measurements decided outliers; warnings for unconstrained measurements and
    skipped lines. A stopped solve is not judged."""
    from graphloc.pipelines.team_graph.verdict import ConsistencyTest

    test = ConsistencyTest()
    limit = test.max_normalized_chi2
    failures, warnings = [], []
    for kind, row in sorted(metrics["factors"].items()):
        if row["normalized_chi2"] is not None and row["normalized_chi2"] > limit:
            failures.append(
                f"{kind}: normalized chi-square {row['normalized_chi2']:.3g} over {row['count']} "
                f"factors > {limit:g}: the residuals exceed the file's noise"
            )
    nullable, null = metrics["decisions"]["with_null"], metrics["decisions"]["decided_null"]
    share = test.max_null_share
    if nullable and null / nullable > share:
        failures.append(
            f"{null} of {nullable} measurements with a null component decided outliers "
            f"(> {share:.0%}): a solution that explains its measurements by calling most of "
            "them outliers (the file's noise understated, or a file with that many outliers)"
        )
    if metrics["decisions"]["never_spanned"]:
        warnings.append(
            f"{metrics['decisions']['never_spanned']} measurements with candidates no later "
            "edge constrained: their first candidate was kept, undecided"
        )
    lost = {k: n for k, n in metrics["skipped"]["counts"].items() if k != "switch_variable"}
    if lost:  # (Vertigo's switch variables are read: the null components replace them)
        counts = ", ".join(f"{k} {n}" for k, n in lost.items())
        warnings.append(f"{sum(lost.values())} lines skipped ({counts})")
    consistent = None if metrics["partial"] else not failures
    return {"consistent": consistent, "failures": failures, "warnings": warnings}


def _get(values, key, dim):
    return values.atPose2(key) if dim == 2 else values.atPose3(key)


def _row(pose, dim: int) -> list:
    if dim == 2:
        return [pose.x(), pose.y(), pose.theta()]
    q = pose.rotation().toQuaternion()
    return [*pose.translation(), q.x(), q.y(), q.z(), q.w()]


def metrics_of(result: dict, mode: str, truth_xy: np.ndarray | None) -> dict:
    graph, truth, choices = result["graph"], result["truth"], result["choices"]
    ambiguous = [i for i, m in enumerate(result["measurements"]) if m.ambiguous]
    decisions = {"ambiguous": len(ambiguous), "with_null": 0, "decided_null": 0,
                 "never_spanned": result["undecided"]}  # fmt: skip
    for i in ambiguous:
        m = result["measurements"][i]
        decisions["with_null"] += int(bool(m.null))
        decisions["decided_null"] += int(m.null and choices.get(i) == len(m.candidates))
    if truth:
        correct = sum(choices.get(i) == k for i, k in truth.items())
        decisions.update(judged=len(truth), correct=correct, mode_accuracy=correct / len(truth))
    out = {
        "source": "pose-graph file", "path": str(graph.path), "format": graph.format,
        "dim": graph.dim, "mode": mode, "partial": result["partial"],
        "poses": len(result["nodes"]), "measurements": len(result["measurements"]),
        "skipped": graph.skips.as_dict(), "decisions": decisions, "engine": result["stats"],
        "factors": result["factors"], "cpu_s": result["cpu"],
    }  # fmt: skip
    out["consistency"] = verdict(out)
    out["consistent"] = out["consistency"]["consistent"]
    if result["latency"]:
        t = np.asarray(result["latency"]) * 1e3
        out["step_cpu_ms"] = {"p50": float(np.median(t)), "p95": float(np.percentile(t, 95)),
                              "max": float(t.max()), "steps": int(t.size)}  # fmt: skip
    if truth_xy is not None:
        d = graph.dim
        n = min(len(truth_xy), int(max(result["nodes"])) + 1)
        rows = [k for k, node in enumerate(result["nodes"]) if node < n]
        est, ref = result["poses"][rows, :d], truth_xy[[result["nodes"][k] for k in rows], :d]
        out["position_rmse_m"] = float(np.sqrt(np.mean(np.sum((est - ref) ** 2, axis=1))))
        out["position_rmse_note"] = "no alignment: the prior holds the first pose"
    return out


def write_outputs(out: Path, result: dict, metrics: dict, truth_poses) -> list[str]:
    from graphloc.eval import write_tum
    from graphloc.names import out_path, written_whole
    from graphloc.plots import Series, plot_trajectories

    out.mkdir(parents=True, exist_ok=True)
    times = np.asarray(result["nodes"], float)
    written = [write_tum(out_path(out, "trajectory.tum"), times, result["poses"])]
    reference = []
    if truth_poses is not None:
        written.append(write_tum(out_path(out, "groundtruth.tum"), np.arange(len(truth_poses)),
                                 truth_poses))  # fmt: skip
        reference = [Series("ground truth", truth_poses[:, :2])]
    with written_whole(out_path(out, "decisions.csv")) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["measurement", "line", "source", "target", "candidates", "null", "choice",
                    "truth", "correct"])  # fmt: skip
        for i, m in enumerate(result["measurements"]):
            if not m.ambiguous:
                continue
            k, t = result["choices"].get(i), result["truth"].get(i)
            w.writerow([i, m.line, m.source, m.target, len(m.candidates), int(m.null), k,
                        "" if t is None else t, "" if t is None else int(k == t)])  # fmt: skip
    written.append(out / "decisions.csv")
    if result["latency"]:
        with written_whole(out_path(out, "latency.csv")) as tmp, open(tmp, "w") as fh:
            fh.write("step,cpu_s\n")
            fh.writelines(f"{k},{t:.6g}\n" for k, t in enumerate(result["latency"]))
        written.append(out / "latency.csv")
    series = [Series(metrics["mode"], result["poses"][:, :2])]
    written.append(plot_trajectories(out_path(out, "trajectory.png"), series, reference,
                                     title=Path(metrics["path"]).name))  # fmt: skip
    with written_whole(out_path(out, "metrics.json")) as tmp:
        Path(tmp).write_text(json.dumps(metrics, indent=1, default=str) + "\n")
    written.append(out / "metrics.json")
    return [str(p) for p in written]


def run_verb(args, mode: str, opts, stop_flag) -> int:
    """The verb for one pose-graph file (`graphloc.commands.smooth.run_verb` hands it over)."""
    given = opts.pose_graph()
    if getattr(args, "checkpoint", None) or getattr(args, "resume", None):
        raise ValueError(f"{args.run}: --checkpoint / --resume take a graphloc run, not a file")
    with stop_flag() as stop:
        cpu0 = time.process_time()
        graph = read_file(args.run, given)
        truth_poses = None
        if given.get("truth_poses"):
            truth_poses = read_truth(given["truth_poses"], graph.dim)
        stop.phase = "solving"
        result = solve_file(graph, mode, given, stop, progress=not args.no_progress)
        result["cpu"] = time.process_time() - cpu0  # from reading the file
        stop.phase = "writing"
        metrics = metrics_of(result, mode, truth_poses)
        metrics["options"] = given
        write_outputs(Path(args.out), result, metrics, truth_poses)
    summary = {k: metrics[k] for k in ("mode", "partial", "consistent", "poses", "decisions")}
    summary["position_rmse_m"] = metrics.get("position_rmse_m")
    print(json.dumps(summary, indent=1))
    verb = "smooth" if mode == "batch" else "online"
    return verdict_exit(verb, args, metrics["consistency"], result["partial"], opts.strict)
