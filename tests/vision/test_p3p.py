"""graphloc.geometry.p3p: every method recovers the truth on random instances, agrees with
cv2.solveP3P and poselib.p3p, and handles degenerate and malformed input."""

import cv2
import gtsam
import numpy as np
import pytest

from graphloc.candidates import CandidateSet
from graphloc.geometry.p3p import P3PCandidates, solve_p3p
from benchmarks.baselines.p3p_seeds import METHODS, solve_p3p_by_name
from benchmarks.p3p_bench import (
    InstanceConfig,
    opencv_p3p_loop,
    poselib_p3p_loop,
    random_p3p_instances,
    recovered,
)
from graphloc.datasets.feng_deterministic import Seed000Config, simulate_straight_line_trials
from benchmarks.baselines.straight_line import (
    StraightLineBaseline,
    StraightLineConfig,
    localize_by_straight_line,
    straight_line_errors,
)

N_RANDOM = 10_000
N_PEER = 1_000


@pytest.fixture(scope="module")
def instances():
    return random_p3p_instances(N_RANDOM, seed=7)


@pytest.fixture(scope="module")
def peer_instances():
    return random_p3p_instances(N_PEER, seed=11)


def _check_candidates_consistent(c: P3PCandidates, inst):
    """Every valid candidate reprojects all three points onto their bearings and has det(R)=1."""
    R, t, v = c.R_wc[c.valid], c.t_wc[c.valid], c.valid
    owner = np.nonzero(v)[0]
    Xc = np.einsum("mji,mpj->mpi", R, inst.points[owner] - t[:, None, :])
    cosang = np.einsum(
        "mpi,mpi->mp", Xc / np.linalg.norm(Xc, axis=2, keepdims=True), inst.bearings[owner]
    )
    assert (cosang > 1 - 1e-10).all()
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-9)
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-9)


@pytest.mark.parametrize("method", METHODS)
def test_recovers_truth_on_random_instances(instances, method):
    c = solve_p3p_by_name(instances.bearings, instances.points, method=method)
    assert c.R_wc.shape == (N_RANDOM, 4, 3, 3) and c.t_wc.shape == (N_RANDOM, 4, 3)
    assert c.valid.shape == (N_RANDOM, 4) and c.valid.dtype == bool
    ok = recovered(c.R_wc, c.t_wc, c.valid, instances.R_wc, instances.t_wc, tol=1e-6)
    assert ok.mean() >= 0.999, f"{method}: recovered {ok.mean():.5f}"
    # valid candidates are packed first, invalid slots are zero
    assert (np.sort(~c.valid, axis=1) == ~c.valid).all()
    assert (c.R_wc[~c.valid] == 0).all() and np.isinf(c.residual[~c.valid]).all()
    _check_candidates_consistent(c, instances)


def test_methods_agree_with_each_other(instances):
    """All four methods find the same candidate set (same count; each candidate of one is a
    candidate of the other) on >= 99.9% of the instances."""
    ref = solve_p3p_by_name(instances.bearings, instances.points, method="lambdatwist")
    for method in METHODS[1:]:
        other = solve_p3p_by_name(instances.bearings, instances.points, method=method)
        same = _same_sets(
            ref.R_wc, ref.t_wc, ref.valid, other.R_wc, other.t_wc, other.valid, tol=1e-6
        )
        assert same.mean() >= 0.999, f"{method} vs lambdatwist: {same.mean():.5f}"


def _matched(Ra, ta, va, Rb, tb, vb, tol):
    """(N,K) True where candidate k of a has a counterpart in b (or is not valid)."""
    dR = np.linalg.norm(Ra[:, :, None] - Rb[:, None, :], axis=(3, 4))
    dt = np.linalg.norm(ta[:, :, None] - tb[:, None, :], axis=3)
    return ~va | ((dR < tol) & (dt < tol) & vb[:, None, :]).any(axis=2)


def _same_sets(Ra, ta, va, Rb, tb, vb, tol):
    return _matched(Ra, ta, va, Rb, tb, vb, tol).all(axis=1) & _matched(
        Rb, tb, vb, Ra, ta, va, tol
    ).all(axis=1)


@pytest.mark.parametrize("method", METHODS)
def test_agrees_with_opencv_and_poselib(peer_instances, method):
    inst = peer_instances
    ours = solve_p3p_by_name(inst.bearings, inst.points, method=method)
    Rp, tp, vp = poselib_p3p_loop(inst.bearings, inst.points)
    same_poselib = _same_sets(ours.R_wc, ours.t_wc, ours.valid, Rp, tp, vp, tol=1e-6)
    assert same_poselib.mean() >= 0.999, f"{method} vs poselib: {same_poselib.mean():.4f}"
    Rc, tc, vc = opencv_p3p_loop(inst.bearings, inst.points, cv2.SOLVEPNP_P3P)
    same_cv = _same_sets(ours.R_wc, ours.t_wc, ours.valid, Rc, tc, vc, tol=1e-6)
    assert same_cv.mean() >= 0.999, f"{method} vs cv2.solveP3P: {same_cv.mean():.4f}"


def test_polish_keeps_exact_solutions_and_fixes_perturbed_ones(instances):
    plain = solve_p3p(instances.bearings[:2000], instances.points[:2000])
    polished = solve_p3p(instances.bearings[:2000], instances.points[:2000], polish=True)
    assert (polished.valid == plain.valid).all()
    assert np.abs(polished.t_wc - plain.t_wc).max() < 1e-8
    # polish on its own: start from a perturbed truth, Gauss-Newton converges back
    from graphloc.geometry.p3p import _polish_pose, _soa_pose  # noqa: PLC0415
    from graphloc.geometry.p3p_soa import soa  # noqa: PLC0415

    rng = np.random.default_rng(3)
    n = 500
    f, X = instances.bearings[:n], instances.points[:n]
    angle = rng.normal(scale=2e-4, size=(n, 3))
    dR = np.stack([gtsam.Rot3.Expmap(a).matrix() for a in angle])
    R0, t0 = _soa_pose(
        dR @ instances.R_wc[:n], instances.t_wc[:n] + rng.normal(scale=1e-3, size=(n, 3))
    )
    flat = lambda V: tuple(tuple(x[:, 0] for x in v) for v in V)  # noqa: E731
    R1, t1 = _polish_pose(flat(soa(f)), flat(soa(X)), R0, t0, iters=4)
    assert np.abs(np.stack(t1, -1) - instances.t_wc[:n]).max() < 1e-8


def test_candidate_count_parity_and_limits(instances):
    c = solve_p3p(instances.bearings, instances.points)
    counts = c.counts()
    assert counts.min() >= 1 and counts.max() <= 4


def test_near_degenerate_instances():
    """Slivers: a 1 degree field of view, bearings down to 0.005 degrees apart, triangle angles
    down to 0.02 degrees. Either the truth is recovered or the row is honestly empty -- every
    candidate passed as valid reprojects the points."""
    cfg = InstanceConfig(
        half_fov=np.deg2rad(0.5), min_bearing_angle=np.deg2rad(0.005), min_angle=np.deg2rad(0.02)
    )
    inst = random_p3p_instances(5000, seed=5, config=cfg)
    for method in METHODS:
        for polish in (False, True):
            c = solve_p3p_by_name(inst.bearings, inst.points, method=method, polish=polish)
            ok = recovered(c.R_wc, c.t_wc, c.valid, inst.R_wc, inst.t_wc, tol=1e-4)
            assert ok.mean() >= 0.999, f"{method} polish={polish}: {ok.mean():.4f}"
            assert not c.degenerate.any()
            _check_candidates_consistent(c, inst)


def test_degenerate_geometry_gives_invalid_rows():
    inst = random_p3p_instances(8, seed=1)
    f, X = inst.bearings.copy(), inst.points.copy()
    X[0, 2] = X[0, 1]  # coincident points
    X[1, 2] = 0.5 * (X[1, 0] + X[1, 1])  # collinear points
    f[2, 1] = f[2, 0]  # parallel bearings
    f[3, 0, 1] = np.nan  # NaN
    X[4, 1, 0] = np.inf  # inf
    f[5, 2] = 0.0  # zero bearing
    for method in METHODS:
        with np.errstate(all="raise"):  # nothing may leak out as a numpy warning either
            c = solve_p3p_by_name(f, X, method=method)
        assert c.degenerate[:6].all() and not c.degenerate[6:].any()
        assert not c.valid[:6].any()
        assert c.valid[6:].any(axis=1).all()
        assert recovered(c.R_wc, c.t_wc, c.valid, inst.R_wc, inst.t_wc)[6:].all()
        assert np.isfinite(c.R_wc).all() and np.isfinite(c.t_wc).all()


def test_points_behind_camera_are_not_returned():
    """Mirror the points through the camera centre: the only consistent poses would put the
    points behind the camera, so there are fewer (or no) candidates and none is the mirror."""
    inst = random_p3p_instances(2000, seed=2)
    c = solve_p3p(-inst.bearings, inst.points)
    owner = np.nonzero(c.valid)[0]
    R, t = c.R_wc[c.valid], c.t_wc[c.valid]
    depth = np.einsum(
        "mji,mpj,mpi->mp", R, inst.points[owner] - t[:, None, :], -inst.bearings[owner]
    )
    assert (depth > 0).all()


@pytest.mark.parametrize(
    "bad",
    [
        (np.zeros((3, 3)), np.zeros((3, 3))),  # missing batch axis
        (np.zeros((5, 3, 3)), np.zeros((4, 3, 3))),  # mismatched N
        (np.zeros((5, 3, 2)), np.zeros((5, 3, 2))),  # 2D points
        (np.zeros((5, 4, 3)), np.zeros((5, 4, 3))),  # four points
        ([["a"] * 3] * 3, np.zeros((3, 3))),  # not numeric
    ],
)
def test_malformed_shapes_raise_value_error(bad):
    with pytest.raises(ValueError, match="solve_p3p"):
        solve_p3p(*bad)


def test_unknown_method_raises():
    with pytest.raises(ValueError, match="unknown method"):
        solve_p3p_by_name(np.zeros((1, 3, 3)), np.zeros((1, 3, 3)), method="gao")


def test_poses_and_candidate_set():
    inst = random_p3p_instances(1, seed=4)
    c = solve_p3p(inst.bearings, inst.points)
    poses = c.poses(0)
    assert 1 <= len(poses) <= 4 and all(isinstance(p, gtsam.Pose3) for p in poses)
    truth = gtsam.Pose3(gtsam.Rot3(inst.R_wc[0]), inst.t_wc[0])
    assert any(p.equals(truth, 1e-8) for p in poses)
    cs = c.candidate_set(0, time=1.5, observer="climber", observed="team")
    assert isinstance(cs, CandidateSet) and len(cs) == len(poses)
    assert cs.source == "p3p/lambdatwist" and cs.time == 1.5
    assert np.allclose(cs.scores, 1.0)


def test_empty_batch():
    c = solve_p3p(np.zeros((0, 3, 3)), np.zeros((0, 3, 3)))
    assert c.R_wc.shape == (0, 4, 3, 3) and c.valid.shape == (0, 4)


# ------------------------------------------------------------------------ straight-line test + demo


def test_straight_line_errors_by_hand():
    pos = np.zeros((1, 3, 2, 3))
    pos[0, 0, 0] = [0, 0, 0]
    pos[0, 2, 0] = [2, 0, 0]
    pos[0, 1, 0] = [1, 0, 0]  # on the line
    pos[0, 1, 1] = [1, 0.3, 0]  # 0.3 off the line
    pos[0, 0, 1] = pos[0, 2, 1] = [5, 5, 5]
    valid = np.ones((1, 3, 2), bool)
    valid[0, 2, 1] = False
    err = straight_line_errors(pos, valid)
    assert err.shape == (1, 2, 2, 2)
    assert err[0, 0, 0, 0] == pytest.approx(0.0, abs=1e-12)
    assert err[0, 0, 1, 0] == pytest.approx(0.3)
    assert np.isinf(err[0, :, :, 1]).all()  # invalid third candidate
    with pytest.raises(ValueError, match="positions"):
        straight_line_errors(np.zeros((3, 2, 3)), valid)


def test_straight_line_picks_genuine_on_noise_free_seed_setup():
    cfg = Seed000Config(pixel_sigma=0.0, lateral_sigma=0.0)
    trials = simulate_straight_line_trials(300, seed=3, config=cfg)
    choice = localize_by_straight_line(trials.pixels, trials.K, trials.ground)
    chosen = choice.chosen_positions()
    assert np.abs(chosen - trials.positions).max() < 1e-6
    assert (choice.error < 1e-8).all()


def test_straight_line_baseline_commits_on_a_line():
    """Frame-by-frame interface: genuine candidate moves on a line, decoys jump around."""
    rng = np.random.default_rng(0)
    baseline = StraightLineBaseline(StraightLineConfig(spacing=2, max_error=0.003))
    decisions = []
    for k in range(7):
        t = np.vstack([[0.1 * k, 0.05 * k, 2.0], rng.uniform(-2, 2, size=(2, 3))])
        cs = CandidateSet(R=np.repeat(np.eye(3)[None], 3, 0), t=t, scores=np.ones(3), time=float(k))
        decisions.append(baseline.update(cs, None if k == 0 else _identity_odometry()))
    assert not any(d.locked for d in decisions[:4])
    assert all(d.locked and d.committed == 0 for d in decisions[4:])
    with pytest.raises(ValueError, match="time"):
        baseline.update(cs, _identity_odometry())


def _identity_odometry():
    from graphloc.seams import Odometry

    return Odometry(gtsam.Pose3(), np.eye(6) * 1e-4)


def test_p3p_bench_script_small(tmp_path):
    """scripts/bench_p3p.py (`make bench-p3p`) from a folder outside the checkout."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[2] / "scripts" / "bench_p3p.py"
    argv = [sys.executable, str(script), "--out", str(tmp_path), "--n", "300", "--no-progress"]
    done = subprocess.run(argv, capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "| " in done.stdout  # the markdown table
    result = json.loads((tmp_path / "p3p_bench.json").read_text())
    names = {r["solver"] for r in result["rows"]}
    assert {"graphloc.lambdatwist", "cv2.solveP3P[P3P] loop", "poselib.p3p loop"} <= names
    assert all(r["recovery_rate"] > 0.99 for r in result["rows"])
    assert (tmp_path / "p3p_bench.md").exists() and (tmp_path / "p3p_bench.png").exists()
