"""Can MRCLAM Dataset6 online reach 300x real time (issue 52)? GTSAM alone on the team graph
graphloc builds, updated one graph step at a time through iSAM2 under graphloc's own fixed-lag
window (`graphloc.fixed_lag.FixedLagWindow`, the online Session's; GTSAM's
IncrementalFixedLagSmoother re-eliminates at every marginalization and costs several times
more), in variants: the robots as Pose3 (the team graph's factors as
they are) or as Pose2 (every MRCLAM robot is planar: BetweenFactorPose2, KnownLandmarkFactorPose2,
BearingRangeFactorPose2, PriorFactorPose2 -- each Pose3 factor's planar part, its noise the
planar marginal of its covariance, its robust kernel kept), with other relinearization settings
(threshold, skip) and lags. For each: the CPU of the updates alone, the realtime factor a run
would reach with today's reading and graph building around them, and the ATE per robot (evo's
SE(2) alignment, as the MRCLAM results are reported) of the estimate each pose had when it left
the window, against graphloc's online solve of the same graph in the same run.

    .venv/bin/python scripts/probe_mrclam_pose2.py --out out/probe_mrclam_pose2 \
        --doc-json docs/results_mrclam_pose2.json

docs/results_speed.md renders it (scripts/bench_speed.py, benchmarks.render.speed).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import gtsam
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MRCLAM = ROOT.parent / "shared" / "data" / "mrclam" / "MRCLAM_Dataset6"
PLANAR = [3, 4, 2]  # Pose3 tangent (rx ry rz tx ty tz) -> Pose2 tangent (x y theta)


def noise_parts(model) -> tuple[np.ndarray, object]:
    """A factor's noise model as (covariance, robust kernel or None)."""
    kernel = None
    if isinstance(model, gtsam.noiseModel.Robust):
        kernel, model = model.robust(), model.noise()
    return np.asarray(model.covariance(), float), kernel


def planar_noise(cov: np.ndarray, kernel) -> object:
    model = gtsam.noiseModel.Gaussian.Covariance(0.5 * (cov + cov.T))
    return model if kernel is None else gtsam.noiseModel.Robust.Create(kernel, model)


def pose2(p: gtsam.Pose3) -> gtsam.Pose2:
    t = p.translation()
    return gtsam.Pose2(float(t[0]), float(t[1]), float(p.rotation().yaw()))


def pose3(p: gtsam.Pose2) -> gtsam.Pose3:
    return gtsam.Pose3(gtsam.Rot3.Yaw(p.theta()), np.array([p.x(), p.y(), 0.0]))


def known_landmark_parts(f) -> tuple[np.ndarray, np.ndarray]:
    """KnownLandmarkFactorPose3's landmark and measured body-frame point (no accessors): its
    error pose.transformTo(L) - m at the identity and at a quarter turn about z."""
    values = gtsam.Values()
    key = f.keys()[0]
    values.insert(key, gtsam.Pose3())
    e0 = np.asarray(f.unwhitenedError(values))
    values.update(key, gtsam.Pose3(gtsam.Rot3.Yaw(math.pi / 2), np.zeros(3)))
    e1 = np.asarray(f.unwhitenedError(values))
    # e0 - e1 = (I - Rz^T) L in the plane
    Rt = gtsam.Rot3.Yaw(math.pi / 2).matrix().T[:2, :2]
    L = np.linalg.solve(np.eye(2) - Rt, (e0 - e1)[:2])
    return L, L - e0[:2]


def to_pose2(f):
    """The Pose2 factor of a planar robot's Pose3 factor."""
    cov, kernel = noise_parts(f.noiseModel())
    if isinstance(f, gtsam.BetweenFactorPose3):
        noise = planar_noise(cov[np.ix_(PLANAR, PLANAR)], kernel)
        return gtsam.BetweenFactorPose2(f.keys()[0], f.keys()[1], pose2(f.measured()), noise)
    if isinstance(f, gtsam.PriorFactorPose3):
        noise = planar_noise(cov[np.ix_(PLANAR, PLANAR)], kernel)
        return gtsam.PriorFactorPose2(f.keys()[0], pose2(f.prior()), noise)
    if isinstance(f, gtsam.KnownLandmarkFactorPose3):
        L, m = known_landmark_parts(f)
        return gtsam.KnownLandmarkFactorPose2(f.keys()[0], L, m, planar_noise(cov[:2, :2], kernel))
    if isinstance(f, gtsam.BearingRangeFactorPose3):
        d = f.measured().bearing().point3()
        noise = planar_noise(cov[np.ix_([0, 2], [0, 2])], kernel)  # in-plane bearing, range
        return gtsam.BearingRangeFactorPose2(
            f.keys()[0],
            f.keys()[1],
            gtsam.Rot2(float(math.atan2(d[1], d[0]))),
            float(f.measured().range()),
            noise,
        )
    raise TypeError(f"no Pose2 form for {type(f).__name__}")


def threshold(session_cfg, planar: bool, scale: float):
    """iSAM2's relinearization threshold map of the session (rotation, translation), scaled."""
    rot, trans = session_cfg.relinearize_threshold * scale, session_cfg.relinearize_translation
    trans = (trans if trans > 0 else session_cfg.relinearize_threshold) * scale
    out = gtsam.ISAM2ThresholdMap()
    out.insert(("x", np.array([trans, trans, rot] if planar else [rot] * 3 + [trans] * 3)))
    return out


def fixed_lag(graph, planar: bool, lag: float, scale: float, skip: int) -> dict:
    """The graph's steps through iSAM2 as the online Session sets it up (its relinearization
    map scaled by `scale`, every `skip` updates) under graphloc's own fixed-lag window
    (`graphloc.fixed_lag.FixedLagWindow`, lag > 0; 0: full smoothing), one update per step, the
    factors added at their step; the CPU of the updates and the final estimate (a marginalized
    pose's frozen at its marginalization, as the online Session's)."""
    from graphloc.fixed_lag import FixedLagWindow
    from graphloc.keys import decode
    from graphloc.pipelines.team_graph.predict import predict

    cfg = replace(graph.config.session_config("online", graph.precision), lag=lag)
    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(threshold(cfg, planar, scale))
    params.relinearizeSkip = skip
    params.setFactorization(cfg.factorization)
    params.enablePartialRelinearizationCheck = cfg.partial_relinearization_check
    params.findUnusedFactorSlots = lag > 0
    step = gtsam.ISAM2GaussNewtonParams()
    step.setWildfireThreshold(cfg.wildfire_threshold)
    params.setOptimizationParams(step)
    isam = gtsam.ISAM2(params)
    window = FixedLagWindow(isam, cfg) if lag > 0 else None
    known, cpu, latest = set(), 0.0, {}
    for t, group in graph.steps:
        factors, values, new = gtsam.NonlinearFactorGraph(), gtsam.Values(), []
        for f, _ in group:
            if not all(key in graph.initial for key in f.keys()):
                continue  # a factor on a variable without a guess (the Session holds it)
            factors.add(to_pose2(f) if planar else f)
            for key in f.keys():
                if key not in known:  # as the online Pass: from the robot's latest estimate
                    known.add(key)
                    v = predict(graph, key, decode(key), latest, None)
                    values.insert(key, pose2(v) if planar else v)
                    new.append(key)
        c0 = time.process_time()
        if window is None:
            isam.update(factors, values)
        else:
            window.update(factors, values, float(t))
        cpu += time.process_time() - c0
        if new:  # the new poses' estimates: the next predictions' start (not timed)
            est = isam.calculateEstimate(new)
            for key in new:
                _, r, k = decode(key)
                p = pose3(est.atPose2(key)) if planar else est.atPose3(key)
                if k >= latest.get(r, (-1, None))[0]:
                    latest[r] = (k, p)
    estimate = isam.calculateEstimate() if window is None else window.estimate()
    rows = {}
    for key in estimate.keys():
        _, r, k = decode(key)
        if planar:
            p = pose3(estimate.atPose2(key))
        else:
            p = estimate.atPose3(key)
        q = p.rotation().toQuaternion()
        rows[(r, k)] = np.r_[p.translation(), q.x(), q.y(), q.z(), q.w()]
    return {"update_cpu_s": cpu, "rows": rows}


def ate(result, run, rows=None) -> dict:
    """Per robot ATE RMSE [m] of `result`'s estimate (or of `rows` (robot, index) -> x y z q)."""
    from graphloc.pipelines.report import evaluate

    if rows is not None:
        estimate = [np.full_like(e, np.nan) for e in result.estimate]
        for (r, k), row in rows.items():
            estimate[r][k] = row
        result = replace(result, estimate=estimate)
    metrics = evaluate(result, run, align="se2")
    return {
        n: e["online"]["ate_rmse"]
        for n, e in metrics["per_robot"].items()
        if isinstance(e.get("online"), dict) and "ate_rmse" in e["online"]
    }


def main(argv=None) -> int:
    from graphloc.datasets import open_run
    from graphloc.pipelines.team_graph import default_lag, solve
    from graphloc.runner.team_run import team_graph
    from graphloc.pipelines.team_graph.options import RunOptions

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/probe_mrclam_pose2"))
    parser.add_argument("--run", type=Path, default=MRCLAM)
    parser.add_argument("--doc-json", type=Path, help="also write the JSON here (docs/)")
    args = parser.parse_args(argv)
    if not args.run.is_dir():
        print(f"{args.run}: no such directory (MRCLAM Dataset6)", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    config = RunOptions().graph_config()
    open_run(args.run)  # once untimed (module loading), as scripts/bench_speed.py
    c0 = time.process_time()
    run = open_run(args.run)
    read = time.process_time() - c0
    config = replace(config, lag=float(default_lag(run, config)))
    graph = team_graph(run, config)
    build = time.process_time() - c0 - read
    c1 = time.process_time()
    result = solve(graph, "online")
    solve_cpu = time.process_time() - c1
    duration = float(max(t[-1] for t in result.node_times if len(t)) - run.start_time)
    cfg = graph.config.session_config("online", graph.precision)
    base_ate = ate(result, run)
    command = "scripts/probe_mrclam_pose2.py " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    report = {
        "command": command,
        "run": str(args.run.name),
        "duration_s": duration,
        "steps": len(graph.steps),
        "lag_s": config.lag,
        "read_cpu_s": read,
        "build_cpu_s": build,
        "graphloc_online": {
            "solve_cpu_s": solve_cpu,
            "update_cpu_s": float(result.step_log[:, 3].sum()),
            "realtime_factor": duration / (read + build + solve_cpu),
            "ate_rmse_m": base_ate,
        },
        "relinearize": {
            "threshold": cfg.relinearize_threshold,
            "skip": cfg.relinearize_skip,
            "translation": cfg.relinearize_translation,
        },
        "target_realtime_factor": 300.0,
        "variants": [],
    }
    print(json.dumps({k: v for k, v in report.items() if k != "variants"}), flush=True)
    lag = config.lag
    skip = cfg.relinearize_skip
    variants = [
        ("Pose3", lag, 1.0, skip),
        ("Pose2", lag, 1.0, skip),
        ("Pose3", lag, 1.0, 3 * skip),
        ("Pose2", lag, 1.0, 3 * skip),
        ("Pose3", lag, 4.0, skip),
        ("Pose2", lag, 4.0, skip),
        ("Pose3", 0.5 * lag, 1.0, skip),
        ("Pose2", 0.5 * lag, 1.0, skip),
        ("Pose2", 2.0 * lag, 1.0, skip),
    ]
    for kind, v_lag, scale, v_skip in variants:
        probe = fixed_lag(graph, kind == "Pose2", v_lag, scale, v_skip)
        a = ate(result, run, probe["rows"])
        cpu = probe["update_cpu_s"]
        row = {
            "variables": kind,
            "lag_s": v_lag,
            "threshold_scale": scale,
            "relinearize_skip": v_skip,
            "update_cpu_s": cpu,
            "update_only_realtime_factor": duration / cpu,
            "end_to_end_realtime_factor": duration / (read + build + cpu),
            "ate_rmse_m": a,
            "ate_over_graphloc": {n: a[n] / base_ate[n] for n in a if n in base_ate},
        }
        row["worst_ate_over_graphloc"] = max(row["ate_over_graphloc"].values())
        report["variants"].append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "ate_rmse_m"}), flush=True)
    text = json.dumps(report, indent=1) + "\n"
    (args.out / "probe_mrclam_pose2.json").write_text(text)
    if args.doc_json:
        args.doc_json.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
