"""graphloc.eval (evo-based ATE / RPE with SE(2) alignment, TUM files) and graphloc.plots."""

import numpy as np
import pytest

from graphloc.eval import ate_over_time, planar_to_evo, read_tum, trajectory_metrics, write_tum
from graphloc.plots import Series, plot_series, plot_trajectories


def _circle(t):
    ang = 0.1 * t
    return np.stack([3 * np.cos(ang), 3 * np.sin(ang), ang + np.pi / 2], axis=1)


def _transform(poses, yaw, tx, ty):
    c, s = np.cos(yaw), np.sin(yaw)
    out = poses.copy()
    out[:, 0] = c * poses[:, 0] - s * poses[:, 1] + tx
    out[:, 1] = s * poses[:, 0] + c * poses[:, 1] + ty
    out[:, 2] = poses[:, 2] + yaw
    return out


def test_se2_alignment_removes_rigid_offset_only():
    t = np.arange(0, 60, 0.25)
    gt = _circle(t)
    moved = _transform(gt, 0.3, 1.0, -2.0)
    assert trajectory_metrics(planar_to_evo(t, gt), planar_to_evo(t, moved)).ate_rmse < 1e-9
    unaligned = trajectory_metrics(planar_to_evo(t, gt), planar_to_evo(t, moved), align="none")
    assert unaligned.ate_rmse > 1.0
    # a non-rigid error survives alignment, with the analytic RMSE of a constant radial offset
    bigger = gt.copy()
    bigger[:, :2] *= (
        1.1  # radius 3.3 vs 3.0 over a full circle: error 0.3 everywhere after alignment
    )
    t_full = np.linspace(0, 2 * np.pi / 0.1, 400, endpoint=False)
    g, b = _circle(t_full), _circle(t_full)
    b[:, :2] *= 1.1
    m = trajectory_metrics(planar_to_evo(t_full, g), planar_to_evo(t_full, b))
    assert m.ate_rmse == pytest.approx(0.3, abs=1e-6) and m.n_matched == 400


def test_rpe_measures_local_drift():
    t = np.arange(0, 60, 0.25)
    gt = _circle(t)
    est = gt.copy()
    est[:, 0] += 0.01 * t  # 1 cm/s drift along x
    m = trajectory_metrics(
        planar_to_evo(t, gt), planar_to_evo(t, est), align="none", rpe_delta_s=1.0
    )
    assert m.rpe_delta_s == pytest.approx(1.0)
    assert m.rpe_trans_rmse == pytest.approx(0.01, rel=0.05)


def test_association_and_bad_input():
    t = np.arange(0, 10, 0.1)
    gt = _circle(t)
    est_t = np.arange(0, 10, 0.5) + 0.004  # within the default 0.02 s
    m = trajectory_metrics(planar_to_evo(t, gt), planar_to_evo(est_t, _circle(est_t)))
    assert m.n_matched == 20 and m.ate_rmse < 0.01
    with pytest.raises(ValueError, match="only 0"):
        trajectory_metrics(planar_to_evo(t, gt), planar_to_evo(t + 100, gt))
    with pytest.raises(ValueError, match="NaN"):
        planar_to_evo(t, np.where(t[:, None] > 5, np.nan, gt))
    with pytest.raises(ValueError, match="align"):
        trajectory_metrics(planar_to_evo(t, gt), planar_to_evo(t, gt), align="sim2")
    scaled = trajectory_metrics(
        planar_to_evo(t, gt), planar_to_evo(t, gt * [2, 2, 1]), align="sim3"
    )
    assert scaled.ate_rmse < 1e-6  # Umeyama with scale undoes a uniform scale of the track


def test_tum_roundtrip_and_error_curve(tmp_path):
    t = np.arange(0, 20, 0.25)
    gt = _circle(t)
    path = write_tum(tmp_path / "a.tum", t, gt)
    back = read_tum(path)
    np.testing.assert_allclose(back.positions_xyz[:, :2], gt[:, :2], atol=1e-9)
    times, err = ate_over_time(planar_to_evo(t, gt), back)
    assert times.shape == err.shape == t.shape and err.max() < 1e-6


def test_plots_write_pngs(tmp_path):
    t = np.arange(0, 20, 0.25)
    gt = _circle(t)
    p1 = plot_trajectories(
        tmp_path / "traj.png",
        [Series("est", gt[:, :2] + 0.05)],
        [Series("gt", gt[:, :2])],
        points=np.array([[0.0, 0.0]]),
        title="t",
    )
    p2 = plot_series(
        tmp_path / "err.png", [Series("err", t, 0.01 + 0 * t)], "t [s]", "m", logy=True
    )
    assert p1.stat().st_size > 5000 and p2.stat().st_size > 5000
    with pytest.raises(ValueError, match="positions"):
        plot_trajectories(tmp_path / "bad.png", [Series("bad", t)])


def test_the_options_offer_the_alignments_evaluation_knows():
    from graphloc.eval import ALIGNMENTS
    from graphloc.pipelines.team_graph.options import ALIGNMENTS as OFFERED
    from graphloc.pipelines.team_graph.options import RunOptions

    assert OFFERED == ALIGNMENTS
    with pytest.raises(ValueError, match="align"):
        RunOptions(align="sim2")


def _random_trajectory(rng, n, planar):
    """A wandering 3D (or planar) trajectory with noisy orientations, evo's type."""
    from evo.core.trajectory import PoseTrajectory3D
    from scipy.spatial.transform import Rotation

    xyz = np.cumsum(rng.normal(0, 0.2, (n, 3)), axis=0)
    if planar:
        xyz[:, 2] = 0
        rot = Rotation.from_euler("z", np.cumsum(rng.normal(0, 0.1, n))[:, None])
    else:
        rot = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.1, (n, 3)), axis=0))
    return PoseTrajectory3D(
        positions_xyz=xyz,
        orientations_quat_wxyz=rot.as_quat()[:, [3, 0, 1, 2]],
        timestamps=np.arange(n) * 0.1,
    )


@pytest.mark.parametrize("align", ["none", "se2", "se3", "sim3"])
@pytest.mark.parametrize("delta", [1, 7])
def test_metrics_equal_evos_own_alignment_and_rpe(align, delta):
    """`trajectory_metrics` aligns and computes the RPE over all poses at once; evo's own
    `align` and `RPE` (one 4x4 matrix per pose) on the same pairs give the same numbers."""
    import copy

    from evo.core import metrics

    from graphloc.eval import relative_pose_errors

    rng = np.random.default_rng(delta)
    planar = align == "se2"
    ref = _random_trajectory(rng, 300, planar)
    est = _random_trajectory(rng, 300, planar)
    m = trajectory_metrics(ref, est, align=align, rpe_delta_s=delta * 0.1, associated=True)
    aligned = copy.deepcopy(est)
    if align == "se2":  # evo has no planar alignment: Umeyama on x, y lifted to 3D
        from evo.core import geometry

        R2, t2, _ = geometry.umeyama_alignment(
            est.positions_xyz[:, :2].T, ref.positions_xyz[:, :2].T
        )
        T = np.eye(4)
        T[:2, :2], T[:2, 3] = R2, t2
        aligned.transform(T)
    elif align in ("se3", "sim3"):
        aligned.align(ref, correct_scale=align == "sim3")
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, aligned))
    assert m.ate_rmse == pytest.approx(ape.get_statistic(metrics.StatisticsType.rmse), rel=1e-9)
    for relation, ours in (
        (metrics.PoseRelation.translation_part, m.rpe_trans_rmse),
        (metrics.PoseRelation.rotation_angle_deg, m.rpe_rot_rmse),
    ):
        rpe = metrics.RPE(relation, delta=delta, delta_unit=metrics.Unit.frames, all_pairs=False)
        rpe.process_data((ref, aligned))
        assert ours == pytest.approx(rpe.get_statistic(metrics.StatisticsType.rmse), rel=1e-9)
        assert ours > 1e-3  # the trajectories differ: a test that can fail
    trans, rot = relative_pose_errors(ref, aligned, delta)
    assert len(trans) == len(rot) == len(range(0, 300, delta)) - 1
