"""Four-identical-marker targets (seed 001 III-A, IV-A, IV-C)."""

import itertools

import gtsam
import numpy as np
import pytest

import graphloc.vision.target as target_mod
from graphloc.cameras import PinholeCamera
from graphloc.vision.markers import detect_markers
from graphloc.datasets.render import RenderConfig, render_markers
from graphloc.vision.target import (
    LARGE_TARGET,
    SMALL_TARGET,
    TargetHypothesisConfig,
    predicted_marker_pixels,
)
from benchmarks.baselines.seed001_target import (
    TargetDesignConfig,
    design_cost,
    design_targets,
    predict_pose,
    target_hypotheses,
)

CAM = PinholeCamera.from_fov(752, 480, np.pi / 2)


def look_at(eye, center, roll=0.0):
    """Camera pose in the target frame (R_tc columns = camera axes), z towards `center`."""
    z = center - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 1.0, 0.3])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.column_stack([x, y, z]) @ gtsam.Rot3.Rz(roll).matrix()
    return R, np.asarray(eye, float)


def random_view(rng, dmin=0.7, dmax=1.7):
    c = LARGE_TARGET.points.mean(axis=0)
    while True:
        direction = rng.normal(size=3)
        direction[2] = abs(direction[2]) + 0.8  # from above, like the seed's quadrotor
        direction /= np.linalg.norm(direction)
        R, t = look_at(
            c + rng.uniform(dmin, dmax) * direction,
            c + rng.normal(0, 0.05, 3),
            rng.uniform(-np.pi, np.pi),
        )
        px, vis = predicted_marker_pixels(CAM, LARGE_TARGET, (R, t))
        gaps = np.linalg.norm(px[:, None] - px[None], axis=2) + 1e9 * np.eye(4)
        if vis.all() and gaps.min() > 15:
            return R, t, px


def rotation_error_deg(Ra, Rb):
    return np.degrees(np.linalg.norm(gtsam.Rot3.Logmap(gtsam.Rot3(Ra.T @ Rb))))


def independent_seed_cost(P, w=2 / 3):
    """Seed 001 eq. (1) written out with plain loops (reference for the vectorized cost)."""
    d = [np.linalg.norm(P[i] - P[j]) for i, j in itertools.combinations(range(len(P)), 2)]
    S = [abs(a - b) for a, b in itertools.combinations(d, 2)]
    return w * min(S) + (1 - w) * np.mean(S)


def test_published_tetrahedron_is_a_valid_design():
    cost = design_cost(LARGE_TARGET.points[None], TargetDesignConfig())
    assert cost == pytest.approx(independent_seed_cost(LARGE_TARGET.points))
    assert cost > 0.04  # s_min = 2.98 cm, s_avg = 6.98 cm
    # the same points violate tighter constraints -> -G
    assert design_cost(LARGE_TARGET.points[None], TargetDesignConfig(d_max=0.29)) == -1.0
    assert design_cost(LARGE_TARGET.points[None], TargetDesignConfig(min_height=0.13)) == -1.0
    flat = LARGE_TARGET.points.copy()
    flat[:, 2] = 0.0
    assert design_cost(flat[None], TargetDesignConfig()) == -1.0


def test_nelder_mead_design_is_feasible_and_competitive():
    cfg = TargetDesignConfig(n_starts=5, n_samples=5000, seed=1)
    design = design_targets(cfg)
    assert design.points.shape == (1, 4, 3)
    assert design.cost == pytest.approx(float(design_cost(design.points, cfg)))
    assert design.cost > design.start_costs.max()  # the optimizer improved on every start
    published = float(design_cost(LARGE_TARGET.points[None], cfg))
    assert design.cost > 0.8 * published
    two = design_targets(
        TargetDesignConfig(n_targets=2, n_starts=2, n_samples=20000, maxiter=600, seed=2)
    )
    assert two.points.shape == (2, 4, 3) and two.cost > 0


def test_design_shape_errors():
    with pytest.raises(ValueError, match="points must be"):
        design_cost(np.zeros((4, 3)), TargetDesignConfig())
    with pytest.raises(ValueError, match="no feasible start"):
        design_targets(TargetDesignConfig(d_min=0.29, d_max=0.30, n_samples=100))


def test_exact_pixels_give_the_true_pose_among_24_assignments(monkeypatch):
    rng = np.random.default_rng(0)
    calls = []
    real = target_mod.solve_p3p

    def counting(bearings, points, **kw):
        calls.append(bearings.shape)
        return real(bearings, points, **kw)

    monkeypatch.setattr(target_mod, "solve_p3p", counting)
    for _ in range(10):
        R, t, px = random_view(rng)
        order = rng.permutation(4)
        cands = target_hypotheses(px[order], CAM, LARGE_TARGET)
        assert cands.meta["n_assignments"] == 24
        assert 1 <= len(cands) <= 96
        pos_err = np.linalg.norm(cands.t - t, axis=1)
        best = int(np.argmax(cands.scores))
        assert pos_err[best] < 1e-6 and rotation_error_deg(cands.R[best], R) < 1e-5
        assign = cands.meta["assignment"][best]
        np.testing.assert_array_equal(
            order[assign], np.arange(4)
        )  # marker j <- detection assign[j]
    assert calls == [(24, 3, 3)] * 10  # ONE batched P3P call per frame


def test_noisy_pixels_and_prediction_restricts_assignments():
    rng = np.random.default_rng(1)
    cfg = TargetHypothesisConfig()
    for _ in range(15):
        R, t, px = random_view(rng)
        noisy = px + rng.normal(0, 0.3, px.shape)
        cands = target_hypotheses(noisy, CAM, LARGE_TARGET, cfg)
        best = int(np.argmax(cands.scores))
        assert (
            np.linalg.norm(cands.t[best] - t) < 0.04 and rotation_error_deg(cands.R[best], R) < 3.0
        )
        near = gtsam.Pose3(gtsam.Rot3(R), t).compose(
            gtsam.Pose3(gtsam.Rot3.Rz(0.02), [0.01, -0.01, 0.01])
        )
        pred = target_hypotheses(noisy, CAM, LARGE_TARGET, cfg, predicted=near)
        assert pred.meta["prediction_used"] and pred.meta["n_assignments"] < 24
        assert np.linalg.norm(pred.t - t, axis=1).min() < 0.04


def test_three_blobs_keep_the_truth_without_a_gate():
    rng = np.random.default_rng(2)
    R, t, px = random_view(rng)
    cands = target_hypotheses(px[[2, 0, 3]], CAM, LARGE_TARGET)
    assert cands.meta["n_assignments"] == 24 and len(cands) > 1
    assert np.linalg.norm(cands.t - t, axis=1).min() < 1e-6
    pred = target_hypotheses(px[[2, 0, 3]], CAM, LARGE_TARGET, predicted=(R, t + 0.005))
    assert pred.meta["n_assignments"] < 24
    assert np.linalg.norm(pred.t - t, axis=1).min() < 1e-6


def test_a_false_fourth_blob_falls_back_to_three_of_four():
    rng = np.random.default_rng(4)
    R, t, px = random_view(rng)
    blobs = np.vstack([px[[3, 1, 0]], [[700.0, 40.0]]])  # marker 2 lost, a clutter blob instead
    cands = target_hypotheses(blobs, CAM, LARGE_TARGET)
    assert cands.meta["fallback"] == "three_of_four" and cands.meta["n_assignments"] == 96
    assert np.linalg.norm(cands.t - t, axis=1).min() < 1e-6
    assert (cands.meta["assignment"] == -1).sum(axis=1).tolist() == [1] * len(cands)
    pred = target_hypotheses(blobs, CAM, LARGE_TARGET, predicted=(R, t + 0.005))
    assert pred.meta["n_assignments"] < 96 and np.linalg.norm(pred.t - t, axis=1).min() < 1e-6
    clean = target_hypotheses(px, CAM, LARGE_TARGET)
    assert clean.meta["fallback"] == ""


def test_rendered_frame_end_to_end():
    rng = np.random.default_rng(3)
    pos, rot = [], []
    for _ in range(8):
        R, t, _ = random_view(rng)
        frame = render_markers(
            CAM,
            (LARGE_TARGET.points - t) @ R,
            LARGE_TARGET.marker_diameter / 2,
            RenderConfig(),
            rng,
        )
        det = detect_markers(frame.image)
        if det.status != "ok":
            continue
        cands = target_hypotheses(det.points, CAM, LARGE_TARGET)
        best = int(np.argmax(cands.scores))
        pos.append(np.linalg.norm(cands.t[best] - t))
        rot.append(rotation_error_deg(cands.R[best], R))
    assert len(pos) >= 7
    assert max(pos) < 0.02 and max(rot) < 1.5


def test_bad_detections_raise():
    with pytest.raises(ValueError, match=r"\(4,2\)"):
        target_hypotheses(np.zeros((5, 2)), CAM)
    with pytest.raises(ValueError, match="NaN"):
        target_hypotheses(np.array([[1.0, 2.0], [3.0, np.nan], [5.0, 6.0], [7.0, 8.0]]), CAM)
    with pytest.raises(ValueError, match="coincide"):
        target_hypotheses(np.array([[1.0, 2.0], [1.0, 2.0], [5.0, 6.0], [7.0, 8.0]]), CAM)
    with pytest.raises(ValueError, match="4-marker"):
        five = target_mod.MarkerTarget(np.vstack([SMALL_TARGET.points, [[0.0, 0.0, 0.2]]]), 0.015)
        target_hypotheses(np.arange(8.0).reshape(4, 2) * 50, CAM, five)


def test_predict_pose_linear_regression_on_se3():
    step = gtsam.Pose3(gtsam.Rot3.RzRyRx(0.05, -0.02, 0.03), [0.02, 0.01, -0.03])
    poses = [gtsam.Pose3(gtsam.Rot3.Rz(0.3), [0.1, 0.2, 1.5])]
    for _ in range(4):
        poses.append(poses[-1].compose(step))
    truth = poses[-1].compose(step)
    for k_R in (2, 3, 5):  # constant body velocity is exactly linear in the tangent space
        assert predict_pose(poses, k_R=k_R).equals(truth, 1e-9)
    assert predict_pose(poses, k_R=1).equals(poses[-1], 1e-12)
    half = poses[-1].compose(gtsam.Pose3.Expmap(0.5 * gtsam.Pose3.Logmap(step)))
    assert predict_pose(poses, times=[0.0, 0.1, 0.2, 0.3, 0.4], t_next=0.45).equals(half, 1e-9)
    with pytest.raises(ValueError, match="increase"):
        predict_pose(poses[:2], times=[1.0, 0.5])
    with pytest.raises(ValueError, match="empty"):
        predict_pose([])
