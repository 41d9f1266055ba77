"""Online at scale (issue 15): the fixed-lag session (bounded variables, marginalized values
kept, factors on them refused), the team graph's lag (dropped factors counted, the whole
trajectory written), latency.csv, a clean stop (partial outputs, exit code 3) and checkpoint /
resume to the same estimates as an uninterrupted run."""

import json
import signal
from dataclasses import replace
from pathlib import Path

import gtsam
import numpy as np
import pytest
from graphloc.datasets import open_run
from helpers import write_synthetic_mrclam

from graphloc.cli import main
from graphloc.commands import smooth
from benchmarks.scale import (
    marginalization_split,
    observation_gaps,
    repeated_online_cpu,
    tenth_error_ratios,
)
from graphloc.keys import decode
from graphloc.pipelines.team_graph import DEFAULT_LAG
from graphloc.runner.team_run import team_graph
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.session import Session, SessionConfig

NOISE = gtsam.noiseModel.Isotropic.Sigma(6, 0.1)


def _chain(session: Session, n: int, dt: float = 0.25) -> None:
    """A pose chain with a prior on every pose (what keeps a fixed-lag window well posed)."""
    for k in range(n):
        _chain_step(session, k, dt)


def _chain_step(session: Session, k: int, dt: float = 0.25) -> None:
    v = gtsam.Values()
    v.insert(k, gtsam.Pose3(gtsam.Rot3(), [k + 0.1, 0, 0]))
    factors = [gtsam.PriorFactorPose3(k, gtsam.Pose3(gtsam.Rot3(), [k, 0, 0]), NOISE)]
    if k:
        step = gtsam.Pose3(gtsam.Rot3(), [1, 0, 0])
        factors.append(gtsam.BetweenFactorPose3(k - 1, k, step, NOISE))
    session.add(factors, v, time=k * dt)


def test_fixed_lag_session_bounds_variables_and_keeps_old_estimates():
    s = Session(SessionConfig(mode="online", lag=2.0))
    _chain(s, 60)
    assert s.fixed_lag and s.live_variables() <= 2 * 2.0 / 0.25 + 2  # lag to 2 lag (batches)
    assert s.marginalized(0) and not s.marginalized(59)
    est = s.estimate()
    assert est.size() == 60  # marginalized poses keep their last estimate
    assert np.allclose([est.atPose3(k).x() for k in range(60)], np.arange(60), atol=0.2)
    assert s.estimate([0, 59]).size() == 2
    with pytest.raises(ValueError, match="marginalized"):
        s.add([gtsam.BetweenFactorPose3(0, 59, gtsam.Pose3(), NOISE)], gtsam.Values(), time=20.0)
    with pytest.raises(ValueError, match="marginalized"):
        s.marginal_covariance(0)
    full = Session(SessionConfig(mode="online"))
    _chain(full, 60)
    assert not full.fixed_lag and full.live_variables() == 60
    with pytest.raises(ValueError, match="lag"):
        SessionConfig(mode="online", lag=-1.0)
    with pytest.raises(ValueError, match="marginalize_every"):
        SessionConfig(mode="online", lag=2.0, marginalize_every=float("nan"))


def test_translation_threshold_map_matches_one_threshold_and_names_uncovered_keys():
    """relinearize_translation equal to relinearize_threshold is the same iSAM2 (the map form
    of one number: identical estimates); a smaller one relinearizes translations the larger
    leaves at their first linearization (initial guesses 3 cm off, conflicting odometry), so
    it ends nearer the batch optimum; a key whose symbol the map does not hold is refused."""
    x = [gtsam.symbol("x", k) for k in range(30)]
    graph, initial, runs = gtsam.NonlinearFactorGraph(), gtsam.Values(), {}
    for trans in (0.0, 0.05, 0.001):
        s = Session(SessionConfig(mode="online", relinearize_translation=trans))
        for k in range(30):
            v = gtsam.Values()
            v.insert(x[k], gtsam.Pose3(gtsam.Rot3(), [k + 0.03, 0.03, 0]))
            f = [gtsam.PriorFactorPose3(x[k], gtsam.Pose3(gtsam.Rot3(), [k, 0, 0]), NOISE)]
            if k:
                step = gtsam.Pose3(gtsam.Rot3.Yaw(0.05), [1, 0.05, 0])
                f.append(gtsam.BetweenFactorPose3(x[k - 1], x[k], step, NOISE))
            s.add(f, v, time=k * 0.25)
            if trans == 0.0:
                for factor in f:
                    graph.add(factor)
                initial.insert(v)
        runs[trans] = np.array([s.estimate([key]).atPose3(key).translation() for key in x])
    optimum = gtsam.LevenbergMarquardtOptimizer(graph, initial).optimize()
    best = np.array([optimum.atPose3(key).translation() for key in x])
    assert np.array_equal(runs[0.0], runs[0.05])
    assert np.abs(runs[0.001] - best).max() < np.abs(runs[0.05] - best).max()
    s = Session(SessionConfig(mode="online", relinearize_translation=0.01))
    v = gtsam.Values()
    v.insert(7, gtsam.Pose3())
    with pytest.raises(ValueError, match="no relinearize threshold"):
        s.add([gtsam.PriorFactorPose3(7, gtsam.Pose3(), NOISE)], v, time=0.0)


def test_marginalize_every_bounds_the_window_and_keeps_the_same_old_estimates():
    """Smaller batches: the window spans lag to lag + marginalize_every; every marginalized
    variable keeps the estimate it had right before it left (its own type, bit for bit)."""
    s = Session(SessionConfig(mode="online", lag=2.0, marginalize_every=0.5))
    live = []
    for k in range(60):
        _chain_step(s, k)
        live.append(s.live_variables())
        if k == 29:  # the last step before pose 20 (stamped 5.0 s) leaves: now - lag > 5.0
            before = s.estimate([20]).atPose3(20)
            assert not s.marginalized(20)
    assert max(live[20:]) <= (2.0 + 0.5) / 0.25 + 1 and min(live[20:]) >= 2.0 / 0.25
    assert s.marginalized(20) and not s.marginalized(52)
    frozen = s.estimate([20]).atPose3(20)
    assert s.estimate().atPose3(20).equals(frozen, 0.0)
    assert frozen.equals(before, 0.0)


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    root = tmp_path_factory.mktemp("scale") / "MRCLAM_Synthetic"
    write_synthetic_mrclam(root, duration=24.0)
    return root


def test_team_graph_lag_writes_whole_trajectory(synthetic):
    run = open_run(synthetic)
    graph = team_graph(run, GraphConfig(lag=3.0))
    lagged = solve(graph, "online")
    full = solve(team_graph(run, GraphConfig()), "online")
    for r in range(len(run.robots)):
        assert np.isfinite(lagged.estimate[r]).all()
        err = np.linalg.norm(lagged.estimate[r][:, :3] - full.estimate[r][:, :3], axis=1)
        assert np.median(err) < 0.1
    log = lagged.step_log
    assert log.shape[1] == 6 and (np.diff(log[:, 0]) > 0).all()
    # the window holds ~lag / dt poses per robot plus landmark anchors, not the whole run
    assert log[-1, 5] < 0.5 * full.step_log[-1, 5]
    assert lagged.lag == 3.0 and full.lag == 0.0 and not lagged.partial


def test_marginalization_split_finds_the_marginalizing_steps(synthetic):
    """A step marginalizes when the live-variable count drops; with marginalize_every 1 s on a
    0.25 s grid about every 4th step of the steady state does, none while the window fills."""
    run = open_run(synthetic)
    result = solve(team_graph(run, GraphConfig(lag=3.0, marginalize_every=1.0)), "online")
    split = marginalization_split(result)
    log = result.step_log
    drops = np.flatnonzero(np.diff(log[:, 5]) < 0) + 1
    assert split["marginalizing_steps"] == len(drops) > 0
    assert log[drops[0], 1] - log[0, 1] >= 3.0  # nothing leaves before the lag has passed
    assert split["share_first10"] < split["share_last10"]
    assert 0.1 < split["share_last10"] < 0.5
    n = len(log) // 10
    other = np.setdiff1d(np.arange(len(log) - n, len(log)), drops)
    assert split["cpu_p95_last10_other_ms"] == pytest.approx(np.percentile(log[other, 3], 95) * 1e3)


def test_factor_across_the_lag_is_dropped_and_counted(synthetic):
    run = open_run(synthetic)
    graph = team_graph(run, GraphConfig(lag=1.0))
    t, group = graph.steps[-1]
    first = next(f for f, kind in graph.steps[1][1] if kind == "odometry")
    old = first.keys()[0]
    late = gtsam.BetweenFactorPose3(
        old, group[0][0].keys()[0], gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 1.0)
    )
    graph.steps[-1] = (t, group + [(late, "odometry")])
    result = solve(graph, "online")
    assert result.dropped == {"odometry": 1}


def test_cli_latency_csv_and_auto_lag(synthetic, tmp_path):
    out = tmp_path / "on"
    assert main(["online", str(synthetic), "--out", str(out), "--no-progress"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["lag_s"] == DEFAULT_LAG and m["partial"] is False
    assert m["steps_done"] == m["steps_total"]
    rows = (out / "latency.csv").read_text().splitlines()
    assert rows[0] == "step,time,latency_s,cpu_s,factors,variables"
    assert len(rows) - 1 == m["counts"]["steps"] > 90 and (out / "latency.png").is_file()
    trend = m["latency_trend"]
    assert trend["variables_end"] <= trend["variables_max"]


def _stop_after(monkeypatch, n: int) -> None:
    """SIGTERM delivered to this process when the solve checks its stop flag the n-th time."""
    calls = {"n": 0}
    original = smooth.StopFlag.__call__

    def call(self):
        calls["n"] += 1
        if calls["n"] == n:
            signal.raise_signal(signal.SIGTERM)
        return original(self)

    monkeypatch.setattr(smooth.StopFlag, "__call__", call)


def test_clean_stop_writes_partial_outputs(synthetic, tmp_path, monkeypatch):
    _stop_after(monkeypatch, 30)
    for verb in ("online", "smooth"):
        out = tmp_path / verb
        code = main([verb, str(synthetic), "--out", str(out), "--no-progress"])
        assert code == smooth.EXIT_STOPPED
        m = json.loads((out / "metrics.json").read_text())
        assert m["partial"] is True and m["stopped_by"] == "SIGTERM"
        mode = "online" if verb == "online" else "batch"
        assert (out / f"robot1_{mode}.tum").is_file()  # the estimate so far is kept
        # what is derived from the run's own tables is left out, and said so
        assert not (out / "robot1_dead_reckoning.tum").exists()
        assert "robot1_dead_reckoning.tum" in m["skipped_outputs"]
        monkeypatch.undo()
        _stop_after(monkeypatch, 2)  # batch: the stop flag is checked between LM iterations
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL


def _tum(out: Path) -> dict:
    return {p.name: p.read_text() for p in sorted(out.glob("*_online.tum"))}


def _resume_once(synthetic, tmp_path, monkeypatch, whole: Path, stop_at: int) -> None:
    tmp_path.mkdir(exist_ok=True)
    ck = tmp_path / "run.ckpt"
    _stop_after(monkeypatch, stop_at)
    args = [
        "online",
        str(synthetic),
        "--no-progress",
        "--checkpoint",
        str(ck),
        "--checkpoint-every",
        "20",
    ]
    assert main([*args, "--out", str(tmp_path / "stopped")]) == smooth.EXIT_STOPPED
    monkeypatch.undo()
    assert ck.read_bytes().startswith(b'{"format": "graphloc-online-checkpoint"')
    assert main([*args, "--out", str(tmp_path / "resumed"), "--resume", str(ck)]) == 0
    assert _tum(tmp_path / "resumed") == _tum(whole) and _tum(whole)


def test_resume_matches_uninterrupted_run(synthetic, tmp_path, monkeypatch):
    whole = tmp_path / "whole"
    assert main(["online", str(synthetic), "--out", str(whole), "--no-progress"]) == 0
    _resume_once(synthetic, tmp_path, monkeypatch, whole, 45)
    # another configuration is refused
    assert (
        main(
            [
                "online",
                str(synthetic),
                "--out",
                str(tmp_path / "x"),
                "--no-progress",
                "--lag",
                "2",
                "--resume",
                str(tmp_path / "run.ckpt"),
            ]
        )
        == 2
    )


@pytest.mark.slow
def test_resume_after_ten_random_stops(synthetic, tmp_path, monkeypatch):
    whole = tmp_path / "whole"
    assert main(["online", str(synthetic), "--out", str(whole), "--no-progress"]) == 0
    for i, stop_at in enumerate(np.random.default_rng(15).integers(2, 90, 10)):
        _resume_once(synthetic, tmp_path / str(i), monkeypatch, whole, int(stop_at))


def test_replayed_run_and_gtsam_only_batch(synthetic):
    from benchmarks.scale import (
        gtsam_only_batch,
        online_profile,
        replay_graph,
    )

    graph = team_graph(open_run(synthetic), GraphConfig())
    long = replay_graph(graph, 3)
    assert len(long.steps) == 3 * len(graph.steps) and len(long.initial) == 3 * len(graph.initial)
    result, cpu, samples = online_profile(long, 3.0, rss_every=50)
    assert not result.dropped and cpu > 0 and len(samples) >= 3
    for r, rows in enumerate(result.estimate):  # every copy retraces the first one
        n = len(graph.node_times[r])
        assert np.allclose(rows[2 * n :, :3], rows[:n, :3], atol=0.1)
    alone = gtsam_only_batch(graph)
    batch = solve(graph, "batch")
    assert alone["variables"] == len(graph.initial) and alone["iterations"] >= 1
    assert np.isfinite(alone["error"]) and batch.wall_s > 0


def test_fixed_lag_with_cross_links_and_extra_updates_matches_full_smoothing():
    """Two robots linked at every step (inter-robot factors cross the stamp groups), relinearized
    at every update with extra updates: marginalizing the oldest stamps as leaves leaves the
    estimates of the whole run near full iSAM2's, and the window stays bounded."""
    noise = gtsam.noiseModel.Isotropic.Sigma(6, 0.05)

    def run(config: SessionConfig) -> Session:
        s = Session(config)
        rng = np.random.default_rng(3)  # the same initial guesses for both
        for k in range(80):
            v = gtsam.Values()
            factors = []
            for r in (0, 1):
                key = 1000 * r + k
                v.insert(key, gtsam.Pose3(gtsam.Rot3(), [k + 0.3 * rng.standard_normal(), r, 0]))
                truth = gtsam.Pose3(gtsam.Rot3(), [k, r, 0])
                if k % 5 == 0:
                    factors.append(gtsam.PriorFactorPose3(key, truth, noise))
                if k:
                    step = gtsam.Pose3(gtsam.Rot3(), [1, 0, 0])
                    factors.append(gtsam.BetweenFactorPose3(key - 1, key, step, noise))
            link = gtsam.Pose3(gtsam.Rot3(), [0, 1, 0])
            factors.append(gtsam.BetweenFactorPose3(k, 1000 + k, link, noise))
            s.add(factors, v, time=0.25 * k)
        return s

    base = dict(mode="online", relinearize_skip=1, extra_updates=2, relinearize_threshold=0.01)
    lagged = run(SessionConfig(**base, lag=2.0, marginalize_every=0.25))
    full = run(SessionConfig(**base))
    assert lagged.marginalized(0) and lagged.live_variables() <= 2 * (2.0 + 0.25) / 0.25 + 2
    a, b = lagged.estimate(), full.estimate()
    err = [
        np.linalg.norm(a.atPose3(k).translation() - b.atPose3(k).translation()) for k in b.keys()
    ]
    assert max(err) < 0.05


def test_observation_gaps_find_a_stretch_without_measurements(synthetic):
    """Robot 0's landmark and teammate factors removed between 2 s and 5 s of the run: its
    longest stretch covers those 3 s; a result compared with itself is 1 in every tenth."""
    run = open_run(synthetic)
    graph = team_graph(run, GraphConfig())
    t0 = graph.steps[0][0]

    def robot0_measurement(t, f, kind):
        inside = 2.0 <= t - t0 <= 5.0 and kind in ("landmark", "inter_robot")
        return inside and any(decode(k)[:2] == ("x", 0) for k in f.keys())

    steps = [
        (t, [(f, k) for f, k in group if not robot0_measurement(t, f, k)])
        for t, group in graph.steps
    ]
    before = observation_gaps(graph)
    after = observation_gaps(replace(graph, steps=steps))
    assert before[0]["longest_gap_s"] < 3.0 <= after[0]["longest_gap_s"]
    assert after[0]["gap_start_s"] <= 2.0 + 1e-9
    assert after[0]["observed_steps"] < before[0]["observed_steps"]
    result = solve(graph, "batch")
    ratios = tenth_error_ratios(result, result, run)
    assert all(r is not None and np.allclose(r, 1.0) for r in ratios)


def test_repeated_online_cpu_takes_each_steps_least_time(synthetic):
    """Two identical solves: the same estimates (difference 0, as resume requires), per-step
    minima no larger than either solve's, and no repeats refused."""
    graph = team_graph(open_run(synthetic), GraphConfig())
    out = repeated_online_cpu(graph, 3.0, 2)
    assert out["repeats"] == 2 and out["max_estimate_difference"] == 0.0
    assert out["cpu_s_least"] == min(out["cpu_s_each"])
    assert 0 < out["cpu_p95_first10_ms"] <= out["cpu_max_ms"]
    with pytest.raises(ValueError, match="repeats"):
        repeated_online_cpu(graph, 3.0, 0)
