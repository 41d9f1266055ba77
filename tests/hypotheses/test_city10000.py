"""City10000-style pose graphs with discrete alternatives: the reader
(graphloc.datasets.pose_graph_file) and the multi-hypothesis engine
(graphloc.hypotheses.pose_graph) on small synthetic graphs with known truth (our own grid
walk, noise and wrong candidates) and on the first steps of City10000."""

import json
import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import X

from graphloc.datasets.pose_graph_file import (
    Measurement,
    group_steps,
    permute_candidates,
    read_pose_graph,
)
from graphloc.hypotheses.pose_graph import PoseGraphConfig, PoseGraphHypotheses


# ---- a synthetic ambiguous pose graph --------------------------------------------------------
def grid_walk(n: int, seed: int, every: int = 12, outliers: int = 0, dim: int = 2):
    """A robot walking 1 m steps on a 6 x 6 m grid (turns at random), loop closures to earlier
    poses within 0.6 m, every `every`-th odometry edge ambiguous (the truth and a wrong
    candidate, turned by 0.6-1.0 rad and shifted sideways), `outliers` random loop closures
    flagged with a null component. Lines written in City10000's format (2D) or g2o (3D)."""
    rng = np.random.default_rng(seed)
    sig = np.array([0.02, 0.02, 0.005])
    poses = [gtsam.Pose2()]
    for _ in range(n - 1):
        p = poses[-1]
        turn = rng.choice([0.0, math.pi / 2, -math.pi / 2], p=[0.6, 0.2, 0.2])
        nxt = p.compose(gtsam.Pose2(1.0, 0.0, turn))
        if max(abs(nxt.x()), abs(nxt.y())) > 3.01:
            nxt = p.compose(gtsam.Pose2(1.0, 0.0, math.pi))
        poses.append(nxt)
    lines, truth_wrong = [], []

    def noisy(rel):
        return rel.compose(gtsam.Pose2(*(rng.normal(size=3) * sig)))

    def fmt(a, b, cands, flag=0):
        nums = " ".join(f"{c.x():.6f} {c.y():.6f} {c.theta():.6f}" for c in cands)
        return f"EDGE2 {a} 1 {b} {flag} {len(cands)} {nums}"

    for k in range(1, n):
        rel = noisy(poses[k - 1].between(poses[k]))
        if k % every == 0:
            side = rng.choice([-1.0, 1.0])
            wrong = rel.compose(gtsam.Pose2(0.3, side * 0.8, side * rng.uniform(0.6, 1.0)))
            lines.append(fmt(k - 1, k, [rel, wrong]))
            truth_wrong.append(len(lines) - 1)
        else:
            lines.append(fmt(k - 1, k, [rel]))
        for j in range(0, k - 3):
            d = poses[j].between(poses[k])
            if math.hypot(d.x(), d.y()) < 0.6 and rng.random() < 0.5:
                lines.append(fmt(j, k, [noisy(d)]))
        if outliers and k > 20 and rng.random() < outliers / n:
            j = int(rng.integers(0, k - 5))
            fake = gtsam.Pose2(*rng.uniform(-3, 3, 2), rng.uniform(-math.pi, math.pi))
            lines.append(fmt(j, k, [fake], flag=1))
    return lines, poses


def write(tmp_path, lines, name="graph.txt"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def run_engine(measurements, dim=2, config=None):
    engine = PoseGraphHypotheses(dim, config)
    steps = group_steps(measurements)
    engine.start(steps[0][0][1].source)
    for step in steps:
        engine.step(step)
    return engine, engine.finish()


# ---- the reader ------------------------------------------------------------------------------
def test_reader_city_format_and_permutation(tmp_path):
    lines, _ = grid_walk(60, seed=1)
    graph = read_pose_graph(write(tmp_path, lines))
    assert graph.dim == 2 and graph.format == "city10000"
    assert len(graph.measurements) == len(lines)
    ambiguous = [i for i, m in enumerate(graph.measurements) if m.ambiguous]
    assert ambiguous and all(len(graph.measurements[i].candidates) == 2 for i in ambiguous)
    a, truth_a = permute_candidates(graph.measurements, seed=3)
    b, truth_b = permute_candidates(graph.measurements, seed=3)
    assert truth_a == truth_b and set(truth_a) == set(ambiguous)
    for i, k in truth_a.items():  # the first-listed candidate is where truth says
        assert np.allclose(a[i].candidates[k], graph.measurements[i].candidates[0])
    seeds = [permute_candidates(graph.measurements, seed=s)[1] for s in range(5)]
    assert len({tuple(sorted(t.items())) for t in seeds}) > 1  # the order really changes


@pytest.mark.parametrize(
    "bad, where",
    [
        ("EDGE2 0 1 1 0 1 0.5 0.1 nan", "field 9 (theta0)"),
        ("EDGE2 0 1 1 0 2 0.5 0.1 0.0", "expected 12 fields"),
        ("EDGE2 0 1 x 0 1 0.5 0.1 0.0", "field 4 (target)"),
        ("EDGE2 0 1 1 5 1 0.5 0.1 0.0", "field 5 (ambiguous-loop flag)"),
        ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 -1", "field 7 (information)"),
    ],
)
def test_reader_errors_name_file_line_and_field(tmp_path, bad, where):
    path = write(tmp_path, ["EDGE2 0 1 1 0 1 1.0 0.0 0.0", bad] if "EDGE2" in bad else [bad])
    line = 2 if "EDGE2" in bad else 1
    with pytest.raises(ValueError) as err:
        read_pose_graph(path)
    assert str(path) in str(err.value) and f"line {line}" in str(err.value)
    assert where in str(err.value)


def test_reader_skips_are_counted(tmp_path):
    lines = ["# comment", "EDGE2 0 1 1 0 1 1 0 0", "EDGE2 1 1 2 0 1 1 0 oops", "LANDMARK 3"]
    graph = read_pose_graph(write(tmp_path, lines), on_error="skip")
    assert len(graph.measurements) == 1
    assert graph.skips.counts == {"parse": 1, "unknown_tag": 1}
    assert "line 3" in graph.skips.first["parse"] and "field 9" in graph.skips.first["parse"]
    with pytest.raises(ValueError, match="no edge read"):
        read_pose_graph(write(tmp_path, ["# nothing"], "empty.txt"))


def test_reader_g2o_alternatives_3d_order_and_mixing(tmp_path):
    info = " ".join(["100", "0", "0", "0", "0", "0", "100", "0", "0", "0", "0", "100"]
                    + ["0", "0", "0", "400", "0", "0", "400", "0", "400"])  # fmt: skip
    turn = "0 1 0 0 0 0.7071 0.7071"
    lines = [
        "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1",
        f"EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 {info}",
        f"EDGE_SE3:QUAT 0 1 1.1 0 0 0 0 0 1 {info}",  # a second measurement, as g2o reads it
        # two candidates (Vertigo's mixture type; its weights are read, not used)
        f"EDGE_SE3_MIXTURE 1 2 2 EDGE_SE3:QUAT 1 1 2 1 0 0 0 0 0 1 {info} "
        f"EDGE_SE3 0.5 1 2 {turn} {info}",
    ]
    graph = read_pose_graph(write(tmp_path, lines))
    assert graph.dim == 3 and len(graph.measurements) == 3 and graph.vertices
    assert [len(m.candidates) for m in graph.measurements] == [1, 1, 2]
    m = graph.measurements[2]
    assert m.ambiguous and not m.null and np.isclose(np.linalg.norm(m.candidates[1][3:]), 1.0)
    assert np.allclose(np.diag(m.information[0]), [400, 400, 400, 100, 100, 100])  # GTSAM order
    with pytest.raises(ValueError, match="mixes 2D and 3D"):
        read_pose_graph(write(tmp_path, lines + ["EDGE_SE2 2 3 1 0 0 1 0 0 1 0 1"], "mix.g2o"))
    loop = lines[:2] + [
        f"EDGE_SE3:QUAT 1 2 1 0 0 0 0 0 1 {info}",
        f"EDGE_SE3:QUAT 0 2 {turn} {info}",
    ]
    null = read_pose_graph(write(tmp_path, loop, "loop.g2o"), null_on_loops=True)
    assert [m.null for m in null.measurements] == [False, False, True]
    bad = lines[:3] + [lines[3].replace("EDGE_SE3 0.5 1 2", "EDGE_SE3 0.5 1 3")]
    with pytest.raises(ValueError, match="line 4: field 40 \\(component 2 target\\)"):
        read_pose_graph(write(tmp_path, bad, "bad.g2o"))


def test_reader_g2o_vertigo_outlier_marks(tmp_path):
    """Vertigo's switchable and max-mixture edges are loop closures with a null component; its
    switch variables are counted, not used; plain edges carry none."""
    info = "100 0 0 100 0 400"
    lines = [
        "VERTEX_SE2 0 0 0 0",
        f"EDGE_SE2 0 1 1 0 0 {info}",
        f"EDGE_SE2 1 2 1 0 0 {info}",
        "VERTEX_SWITCH 3 1",
        "EDGE_SWITCH_PRIOR 3 1 1",
        f"EDGE_SE2_SWITCHABLE 0 2 3 2 0 0 {info}",
        f"EDGE_SE2_MAXMIX 2 0 0.01 -2 0 0 {info}",
    ]
    graph = read_pose_graph(write(tmp_path, lines, "vertigo.g2o"))
    assert [m.null for m in graph.measurements] == [False, False, True, True]
    assert all(len(m.candidates) == 1 for m in graph.measurements)
    assert graph.skips.counts == {"switch_variable": 2}
    engine, estimate = run_engine(graph.measurements)
    assert engine.choices()[2] == 0 and engine.choices()[3] == 0  # both closures fit: kept
    assert np.isclose(estimate.atPose2(X(2)).x(), 2.0, atol=1e-6)


# ---- the engine ------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_engine_decides_every_ambiguous_edge_of_a_synthetic_walk(tmp_path, seed):
    lines, poses = grid_walk(260, seed=seed)
    graph = read_pose_graph(write(tmp_path, lines))
    measurements, truth = permute_candidates(graph.measurements, seed=seed)
    engine, estimate = run_engine(measurements, config=PoseGraphConfig(sigmas=(0.02, 0.02, 0.005)))
    choices = engine.choices()
    assert len(truth) >= 15 and sum(k != 0 for k in truth.values()) >= 5  # not the first
    assert {i: choices[i] for i in truth} == truth
    truth_xy = np.array([[p.x(), p.y()] for p in poses])
    est_xy = np.array(
        [[estimate.atPose2(X(k)).x(), estimate.atPose2(X(k)).y()] for k in range(len(poses))]
    )
    assert rmse(est_xy, truth_xy) < 0.3


def test_engine_rejects_outlier_loop_closures(tmp_path):
    lines, poses = grid_walk(200, seed=4, every=10_000, outliers=15)
    graph = read_pose_graph(write(tmp_path, lines))
    flagged = [i for i, m in enumerate(graph.measurements) if m.null]
    assert len(flagged) >= 5
    engine, estimate = run_engine(
        graph.measurements, config=PoseGraphConfig(sigmas=(0.02, 0.02, 0.005))
    )
    choices = engine.choices()
    assert all(choices[i] == 1 for i in flagged)  # the null component (index K)
    truth_xy = np.array([[p.x(), p.y()] for p in poses])
    est_xy = np.array(
        [[estimate.atPose2(X(k)).x(), estimate.atPose2(X(k)).y()] for k in range(len(poses))]
    )
    assert rmse(est_xy, truth_xy) < 0.3


def test_engine_3d(tmp_path):
    """The same walk lifted to Pose3 (g2o 3D lines, a wrong candidate turned about z)."""
    lines, poses = grid_walk(200, seed=5)
    graph2 = read_pose_graph(write(tmp_path, lines))
    info = "2500 0 0 0 0 0 2500 0 0 0 0 2500 0 0 0 40000 0 0 40000 0 40000"
    out = []
    for m in graph2.measurements:
        for c in m.candidates:
            q = gtsam.Rot3.Rz(c[2]).toQuaternion()
            out.append(f"EDGE_SE3:QUAT {m.source} {m.target} {c[0]} {c[1]} 0 "
                       f"{q.x()} {q.y()} {q.z()} {q.w()} {info}")  # fmt: skip
    graph = read_pose_graph(write(tmp_path, out, "walk3d.g2o"))
    assert graph.dim == 3
    measurements, truth = permute_candidates(graph.measurements, seed=5)
    engine, estimate = run_engine(measurements, dim=3)
    choices = engine.choices()
    assert {i: choices[i] for i in truth} == truth
    est = np.array([estimate.atPose3(X(k)).translation()[:2] for k in range(len(poses))])
    assert rmse(est, np.array([[p.x(), p.y()] for p in poses])) < 0.3


def test_city10000_first_steps():
    path = gtsam.findExampleDataFile("T1_city10000_04.txt")
    graph = read_pose_graph(path, max_edges=1500)
    measurements, truth = permute_candidates(graph.measurements, seed=0)
    engine, _ = run_engine(measurements)
    choices = engine.choices()
    assert len(truth) >= 15
    assert sum(choices[i] == k for i, k in truth.items()) == len(truth)


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a[:, :2] - b[:, :2]) ** 2, axis=1))))


# ---- the verbs -------------------------------------------------------------------------------
def test_smooth_and_online_take_a_pose_graph_file(tmp_path, cli):
    import json

    lines, poses = grid_walk(200, seed=6)
    path = write(tmp_path, lines, "walk.txt")
    truth = tmp_path / "truth.txt"
    truth.write_text("".join(f"{p.x()} {p.y()} {p.theta()}\n" for p in poses), encoding="utf-8")
    for verb in ("smooth", "online"):
        out = tmp_path / verb
        got = cli([verb, str(path), "--out", str(out), "--candidate-seed", "2",
                   "--truth-poses", str(truth)], out=out)  # fmt: skip
        assert got.code == 0, got.err[-2000:]
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["decisions"]["judged"] >= 10
        assert metrics["decisions"]["mode_accuracy"] == 1.0
        assert metrics["position_rmse_m"] < 0.5
        assert (out / "trajectory.tum").read_text().count("\n") == len(poses)
        rows = (out / "decisions.csv").read_text().splitlines()
        assert len(rows) == 1 + metrics["decisions"]["ambiguous"]


def test_pose_graph_options_and_bad_truth_are_one_error(tmp_path, cli, planar_log_template):
    lines, _ = grid_walk(40, seed=7)
    path = write(tmp_path, lines, "walk.txt")
    bad = tmp_path / "bad.txt"
    bad.write_text("0 0 0\n1 0\n", encoding="utf-8")
    out = tmp_path / "o1"
    got = cli(["smooth", str(path), "--out", str(out), "--truth-poses", str(bad)], out=out)
    assert got.code == 2 and "bad.txt: line 2: expected 3 fields" in got.err
    out = tmp_path / "o2"
    got = cli(["smooth", str(planar_log_template), "--out", str(out), "--candidate-seed", "1"],
              out=out)  # fmt: skip
    assert got.code == 2 and "--candidate-seed applies to a pose-graph file" in got.err


def _vertigo_square(tmp_path, outliers: int, seed: int = 5):
    """A g2o file written as Vertigo's generateDataset.py writes one (not by graphloc): a robot
    driving a 10 x 10 m square twice, noisy odometry, every pose of the second lap closing to
    the first (EDGE_SE2_SWITCHABLE with its switch variable and prior), `outliers` random false
    closures (EDGE_SE2_MAXMIX). Returns the path and the true poses."""
    rng = np.random.default_rng(seed)
    info = "400 0 0 400 0 2500"
    lines, poses, (x, y, th) = [], [], (0.0, 0.0, 0.0)
    for k in range(80):
        poses.append(gtsam.Pose2(x, y, th))
        lines.append(f"VERTEX_SE2 {k} {x} {y} {th}")
        x, y, th = x + np.cos(th), y + np.sin(th), th + (np.pi / 2 if k % 10 == 9 else 0.0)
    for k in range(79):
        r = poses[k].between(poses[k + 1])
        dx, dy, dth = rng.normal(0, [0.05, 0.05, 0.02])
        lines.append(f"EDGE_SE2 {k} {k + 1} {r.x() + dx} {r.y() + dy} {r.theta() + dth} {info}")
    for k in range(40, 80):
        r, s = poses[k - 40].between(poses[k]), 80 + k
        closure = f"{k - 40} {k} {s} {r.x()} {r.y()} {r.theta()} {info}"
        lines += [
            f"VERTEX_SWITCH {s} 1",
            f"EDGE_SWITCH_PRIOR {s} 1 1",
            f"EDGE_SE2_SWITCHABLE {closure}",
        ]
    for _ in range(outliers):
        a = int(rng.integers(0, 70))
        b = a + int(rng.integers(3, 10))
        lines.append(f"EDGE_SE2_MAXMIX {a} {b} 0.01 {rng.uniform(-5, 5)} {rng.uniform(-5, 5)} "
                     f"0.3 {info}")  # fmt: skip
    return write(tmp_path, lines, "square.g2o"), poses


def test_smooth_and_validate_read_a_vertigo_outlier_file(tmp_path, cli):
    import json

    path, poses = _vertigo_square(tmp_path, outliers=10)
    got = cli(["validate", str(path)])
    assert got.code == 0, got.err[-2000:]
    report = json.loads(got.out)
    assert report["measurements"]["with_null"] == 50 and report["unreachable_edges"] == 0
    assert report["skipped"]["counts"] == {"switch_variable": 80}
    out = tmp_path / "out"
    got = cli(["smooth", str(path), "--out", str(out), "--no-progress"], out=out)
    assert got.code == 0, got.err[-2000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["decisions"]["decided_null"] == 10  # the ten false closures, no true one
    rows = [r.split(",") for r in (out / "decisions.csv").read_text().splitlines()[1:]]
    nulls = {int(r[0]) for r in rows if r[6] == "1"}  # choice 1 = the null of one candidate
    assert nulls == set(range(79 + 40, 79 + 40 + 10))  # the MAXMIX lines, after the closures
    assert metrics["consistent"] is True and got.err.count("warning") == 0
    # well-formed but wrong: information matrices 100x too tight -> inconsistent, said so
    tight = write(tmp_path, [line.replace("400 0 0 400 0 2500", "40000 0 0 40000 0 250000")
                             for line in path.read_text().splitlines()], "tight.g2o")  # fmt: skip
    out = tmp_path / "tight"
    got = cli(["smooth", str(tight), "--out", str(out), "--no-progress", "--strict"], out=out)
    metrics = json.loads((out / "metrics.json").read_text())
    assert got.code == 5 and metrics["consistent"] is False  # every closure called an outlier
    assert "inconsistent: 50 of 50 measurements with a null component decided outliers" in got.err
    bad = write(tmp_path, path.read_text().splitlines() + ["EDGE_SE2 200 201 1 0 0 1 0 0 1 0 1"],
                "bad.g2o")  # fmt: skip
    got = cli(["validate", str(bad)])
    assert got.code == 2 and "bad.g2o: line " in got.err and "200 is no pose" in got.err


def test_api_doc_block_runs_as_written():
    import re
    from pathlib import Path

    doc = Path(__file__).resolve().parents[2] / "docs" / "api.md"
    blocks = re.findall(r"```python\n(.*?)```", doc.read_text(), flags=re.S)
    block = next(b for b in blocks if "PoseGraphHypotheses" in b)
    namespace = {}
    exec(compile(block, str(doc), "exec"), namespace)
    decided, truth, choices = namespace["decided"], namespace["truth"], namespace["choices"]
    assert decided and all(choices[i] == truth[i] for i in decided)


def test_decisions_with_a_null_are_taken_again_at_the_optimum():
    """`redecided`: a true loop closure decided null (judged against a drifted estimate) is
    taken back, an outlier decided in is taken out, each by its cost at the optimum of the
    other decisions against the null's; the estimate is re-optimized."""
    from graphloc.hypotheses.pose_graph_refine import redecided
    from graphloc.hypotheses.pose_graph_state import Ambiguity

    noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.05, 0.05, 0.01]))
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(), noise))
    values = gtsam.Values()
    step = gtsam.Pose2(1.05, 0, np.pi / 2 + 0.005)  # a square, the odometry's turns a bit wide
    for k in range(4):
        graph.add(gtsam.BetweenFactorPose2(X(k), X(k + 1), step, noise))
    for k in range(5):
        values.insert(X(k), gtsam.Pose2())
    true_loop = gtsam.BetweenFactorPose2(X(0), X(4), gtsam.Pose2(), noise)
    outlier = gtsam.BetweenFactorPose2(X(1), X(3), gtsam.Pose2(3, 3, 1), noise)
    rejected = Ambiguity(0, [true_loop, None], [None], (X(0), X(4)), -1, state="decided", choice=1)
    accepted = Ambiguity(1, [outlier, None], [None], (X(1), X(3)), -1, state="decided", choice=0)
    accepted.slot = graph.size()
    graph.add(outlier)
    start = gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()
    estimate, changed = redecided(graph, start, [rejected, accepted], 16.27, rounds=5)
    assert changed == 2 and rejected.choice == 0 and accepted.choice == 1
    assert 2 * true_loop.error(estimate) < 16.27 < 2 * outlier.error(estimate)
    gap = [np.hypot(v.atPose2(X(4)).x(), v.atPose2(X(4)).y()) for v in (start, estimate)]
    assert gap[1] < 0.2 * gap[0]  # the loop closes


def _straight_run(loop_y: float, odometry_sigmas, ambiguous_at: int | None = None):
    """Measurements of a 20 m straight run in 1 m steps (odometry (1, 0, 0), information from
    `odometry_sigmas`), the edge into pose `ambiguous_at` with two near-equal candidates, and a
    loop closure 0 -> 20 with a null component measuring pose 20 at (20, `loop_y`, 0) under
    sigmas 5 cm / 1 deg: its predicted chi-square is (loop_y / 0.05)^2, the whole residual
    charged to it."""
    info = np.diag(1.0 / np.asarray(odometry_sigmas, float) ** 2)
    loop_info = np.diag(1.0 / np.array([0.05, 0.05, math.radians(1.0)]) ** 2)
    out = []
    for k in range(1, 21):
        near = ((1.0, 0.0, 0.0), (1.0, 0.0, 1e-4)) if k == ambiguous_at else ((1.0, 0.0, 0.0),)
        out.append(Measurement(k, k - 1, k, near, (info,) * len(near)))
    out.append(Measurement(21, 0, 20, ((20.0, loop_y, 0.0),), (loop_info,), null=True))
    return out


def test_the_null_never_crowds_out_every_candidate_of_a_branching():
    """Two branches (an ambiguous odometry edge, its candidates alike) meet a loop closure with
    a null component whose residual against the drifted chain is 0.4 m: charged wholly to it
    the candidate predicts chi-square 64, above the null's 16.27, so with room for two branches
    the two null children took both places and the closure was decided null unseen; a loose
    chain absorbs it (optimized rise < 1), which only a judgement on the optimized graph shows.
    The best candidate child keeps a place: the closure is accepted."""
    measurements = _straight_run(0.4, (0.1, 0.1, 0.05), ambiguous_at=10)
    config = PoseGraphConfig(max_branches=2, margin=5.0, window=100)
    engine, estimate = run_engine(measurements, config=config)
    assert engine.stats["branchings"] == 1
    assert engine.choices()[20] == 0  # the candidate, not the null (index 1)
    assert abs(estimate.atPose2(X(20)).y() - 0.4) < 0.05


@pytest.mark.parametrize("dof, accepted", [(math.inf, False), (6.0, True)])
def test_heavy_tailed_candidates_cost_a_log_of_their_residual(dof, accepted):
    """`candidate_dof`: a candidate's factor costs dof * log(1 + m / dof) (GTSAM's Cauchy loss,
    `branching.heavy_tailed`) instead of its Mahalanobis^2 m. A stiff chain (the residual stays
    on the closure) and a closure 0.35 m off: m = 49, above the null's 16.27 as a Gaussian, 6
    log(1 + 49 / 6) = 13.3 below it under a Student-t with 6 dof."""
    from graphloc.hypotheses import branching as br

    gaussian = gtsam.noiseModel.Isotropic.Sigma(3, 0.5)
    robust = br.heavy_tailed(gaussian, 6.0)
    factor = gtsam.BetweenFactorPose2(X(0), X(1), gtsam.Pose2(), robust)
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2())
    values.insert(X(1), gtsam.Pose2(1.0, 0.0, 0.0))  # m = 4
    assert 2 * factor.error(values) == pytest.approx(6 * math.log1p(4 / 6))
    assert br.robust_chi2(factor, 4.0) == pytest.approx(6 * math.log1p(4 / 6))
    assert np.allclose(br.covariance_of(factor), gaussian.covariance())
    assert br.heavy_tailed(gaussian, math.inf) is gaussian

    measurements = _straight_run(0.35, (1e-4, 1e-4, 1e-5))
    engine, _ = run_engine(measurements, config=PoseGraphConfig(candidate_dof=dof))
    assert (engine.choices()[20] == 0) == accepted


I3 = "100 0 0 100 0 400"
I6 = " ".join(["100", "0", "0", "0", "0", "0", "100", "0", "0", "0", "0", "100"]
              + ["0", "0", "0", "400", "0", "0", "400", "0", "400"])  # fmt: skip
BAD_VERTIGO = [  # (id, line, the words the error names)
    ("switchable-short", f"EDGE_SE2_SWITCHABLE 0 1 9 1 0 0 {I3[:-4]}", "expected 13 fields"),
    ("maxmix-nan-weight", f"EDGE_SE2_MAXMIX 0 1 nan 1 0 0 {I3}", "field 4 (weight)"),
    ("mixture-no-component", "EDGE_SE2_MIXTURE 0 1 0", "field 4 (component count)"),
    ("mixture-huge-count", "EDGE_SE2_MIXTURE 0 1 1000000000", "field 4 (component count)"),
    ("mixture-count-mismatch", f"EDGE_SE2_MIXTURE 0 1 2 EDGE_SE2 1 0 1 1 0 0 {I3}",
     "with 2 components: expected 30 fields"),
    ("mixture-wrong-tag", f"EDGE_SE2_MIXTURE 0 1 1 VERTEX_SE2 1 0 1 1 0 0 {I3}",
     "field 5 (component 1 tag)"),
    ("mixture-wrong-pair", f"EDGE_SE2_MIXTURE 0 1 1 EDGE_SE2 1 0 2 1 0 0 {I3}",
     "field 8 (component 1 target)"),
    ("se3-switchable-zero-quaternion", f"EDGE_SE3_SWITCHABLE 0 1 9 1 0 0 0 0 0 0 {I6}",
     "field 8 (qx..qw)"),
    ("switchable-not-pd", "EDGE_SE2_SWITCHABLE 0 1 9 1 0 0 1 0 0 1 0 -1", "(information)"),
]  # fmt: skip


@pytest.mark.parametrize("line, names", [pytest.param(c[1], c[2], id=c[0]) for c in BAD_VERTIGO])
def test_a_bad_vertigo_line_is_named_or_counted(tmp_path, cli, line, names):
    """Each malformed robust-edge line: `read_pose_graph` raises naming file, line and field;
    `graphloc validate` (which skips bad lines, as smooth / online do) counts it with that
    message and reads the rest."""
    dim3 = "SE3" in line
    good = f"EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 {I6}" if dim3 else f"EDGE_SE2 0 1 1 0 0 {I3}"
    path = write(tmp_path, [good, line], "bad.g2o")
    with pytest.raises(ValueError) as err:
        read_pose_graph(path)
    assert f"{path}: line 2" in str(err.value) and names in str(err.value)
    got = cli(["validate", str(path)])
    assert got.code == 0 and not got.error_line, got.err
    report = json.loads(got.out)
    assert report["measurements"]["total"] == 1 and report["skipped"]["total"] == 1
    assert names in json.dumps(report["skipped"]["examples"])
