import math

import gtsam
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from graphloc.cameras import ParaboloidOmniCamera, PinholeCamera
from graphloc.vision.mutual import (
    STATUS_DEGENERATE,
    STATUS_INCONSISTENT,
    STATUS_NO_BEARING,
    STATUS_OK,
    MutualConfig,
    localize_three,
)
from graphloc.datasets.render import render_mutual_pixels

# seed 000 section VI: 512 x 512 panoramic cameras; FOV to 35 deg below the horizon so that
# cameras tilted by up to pi/6 still see each other
OMNI = ParaboloidOmniCamera.from_fov(512, max_polar_angle=math.radians(125))


def random_formations(n, rng, max_tilt=0.0, min_angle_deg=15.0):
    """n formations of 3 cameras on the floor (z ~ 0.3 m), 0.5-6 m apart, random headings,
    tilted by up to max_tilt [rad]; all interior angles >= min_angle_deg."""
    t = np.empty((0, 3, 3))
    while len(t) < n:
        xy = rng.uniform(-3.0, 3.0, (4 * n, 3, 2))
        cand = np.concatenate([xy, 0.3 + rng.uniform(-0.02, 0.02, (4 * n, 3, 1))], axis=2)
        sides = np.linalg.norm(cand - np.roll(cand, 1, axis=1), axis=2)
        a, b = cand[:, 1] - cand[:, 0], cand[:, 2] - cand[:, 0]
        area = 0.5 * np.linalg.norm(np.cross(a, b), axis=1)
        # smallest angle via the law of sines: sin(angle) = 2 area / (product of adjacent sides)
        sin_min = 2 * area[:, None] / (sides * np.roll(sides, -1, axis=1))
        keep = (sides.min(axis=1) > 0.5) & (
            np.arcsin(np.clip(sin_min, 0, 1)).min(axis=1) > math.radians(min_angle_deg)
        )
        t = np.concatenate([t, cand[keep]])[:n]
    tilt_axis = rng.normal(size=(3 * n, 3)) * (1, 1, 0)
    tilt_axis /= np.linalg.norm(tilt_axis, axis=1, keepdims=True)
    tilt = Rotation.from_rotvec(tilt_axis * rng.uniform(0.0, max_tilt, (3 * n, 1)))
    yaw = Rotation.from_rotvec(np.outer(rng.uniform(-math.pi, math.pi, 3 * n), [0, 0, 1]))
    return (tilt * yaw).as_matrix().reshape(n, 3, 3, 3), t


def truth_in_frame_1(R, t):
    """R (N,3,3,3), t (N,3,3) in the world -> the same in C1's frame."""
    R1 = R[:, 0]
    return np.einsum("nji,nkjl->nkil", R1, R), np.einsum("nji,nkj->nki", R1, t - t[:, :1])


def seed_noise(shape, rng, sigma=0.5):
    """Seed 000 VI: N(0, 0.5) px displacement in a uniformly random direction."""
    angle = rng.uniform(-math.pi, math.pi, shape[:-1])
    return rng.normal(0.0, sigma, shape[:-1])[..., None] * np.stack(
        [np.cos(angle), np.sin(angle)], -1
    )


def rotation_errors_deg(R_est, R_true):
    rel = np.einsum("...ji,...jk->...ik", R_est, R_true).reshape(-1, 3, 3)
    return np.degrees(Rotation.from_matrix(rel).magnitude())


@pytest.mark.parametrize("max_tilt, planar", [(0.0, True), (0.0, False), (math.pi / 6, False)])
def test_noise_free_exact(max_tilt, planar):
    rng = np.random.default_rng(11)
    R, t = random_formations(300, rng, max_tilt)
    pixels, visible = render_mutual_pixels(R, t, OMNI)
    assert visible[:, ~np.eye(3, dtype=bool)].all()
    baseline = np.linalg.norm(t[:, 1] - t[:, 0], axis=1)
    result = localize_three(pixels, OMNI, baseline, MutualConfig(planar=planar))
    assert (result.status == STATUS_OK).all()
    R_true, t_true = truth_in_frame_1(R, t)
    if planar:  # upright cameras at slightly different heights: only the planar part is recovered
        t_true = t_true * (1, 1, 0)
        np.testing.assert_allclose(result.R[:, :, 2, 2], 1.0, atol=1e-9)
        tol_t, tol_R = 1e-3 * baseline.max(), 1e-2
    else:
        tol_t, tol_R = 1e-9, 1e-9
    assert np.abs(result.t - t_true).max() < tol_t
    if not planar:
        assert np.abs(result.R - R_true).max() < tol_R
    else:  # headings
        yaw_est = np.arctan2(result.R[:, :, 1, 0], result.R[:, :, 0, 0])
        yaw_true = np.arctan2(R_true[:, :, 1, 0], R_true[:, :, 0, 0])
        assert np.abs(np.angle(np.exp(1j * (yaw_est - yaw_true)))).max() < tol_R
    np.testing.assert_allclose(result.closure, 0.0, atol=1e-9 if not planar else 1e-3)
    np.testing.assert_allclose(result.scale, baseline)
    assert (result.condition >= 2 / math.sqrt(3) - 1e-9).all()


def test_planar_exact_when_cameras_at_equal_height():
    rng = np.random.default_rng(12)
    R, t = random_formations(100, rng)
    t[..., 2] = 0.3
    pixels, _ = render_mutual_pixels(R, t, OMNI)
    result = localize_three(
        pixels, OMNI, np.linalg.norm(t[:, 1] - t[:, 0], axis=1), MutualConfig(planar=True)
    )
    R_true, t_true = truth_in_frame_1(R, t)
    assert result.ok.all()
    assert np.abs(result.t - t_true).max() < 1e-9 and np.abs(result.R - R_true).max() < 1e-9


@pytest.mark.parametrize(
    "max_tilt, planar, t_tol, R_tol", [(0.0, True, 0.005, 0.25), (math.pi / 6, False, 0.008, 0.8)]
)
def test_half_pixel_noise_small_error(max_tilt, planar, t_tol, R_tol):
    """0.5 px noise (seed 000 VI). Median errors, relative to the 0.5-6 m baselines; measured
    ~0.23 %/0.11 deg (planar, upright) and ~0.31 %/0.38 deg (3D, tilted up to pi/6)."""
    rng = np.random.default_rng(13)
    R, t = random_formations(400, rng, max_tilt)
    pixels, _ = render_mutual_pixels(R, t, OMNI)
    baseline = np.linalg.norm(t[:, 1] - t[:, 0], axis=1)
    result = localize_three(
        pixels + seed_noise(pixels.shape, rng), OMNI, baseline, MutualConfig(planar=planar)
    )
    ok = result.ok
    assert ok.mean() > 0.97
    R_true, t_true = truth_in_frame_1(R, t)
    if planar:
        t_true = t_true * (1, 1, 0)
    rel_t = np.linalg.norm(result.t - t_true, axis=2)[ok][:, 1:] / baseline[ok, None]
    ang = rotation_errors_deg(result.R[ok][:, 1:], R_true[ok][:, 1:])
    assert np.median(rel_t) < t_tol and np.median(ang) < R_tol
    assert np.abs(result.closure[ok]).max() < math.radians(5.0)
    assert 0 < np.median(result.misfit[ok]) < 0.01  # noise shows in the alignment residual ...
    strict = localize_three(
        pixels + seed_noise(pixels.shape, rng),
        OMNI,
        baseline,
        MutualConfig(planar=planar, max_misfit=1e-6),
    )
    assert (strict.status == STATUS_INCONSISTENT).all()  # ... and a limit below it rejects
    # the condition number predicts the error: ill-conditioned triangles err more
    cond = result.condition[ok]
    worst = rel_t.max(axis=1)
    assert np.median(worst[cond > np.median(cond)]) > np.median(worst[cond <= np.median(cond)])


def test_collinear_and_nearly_collinear_reported():
    rng = np.random.default_rng(14)
    R, t = random_formations(3, rng)
    t[0] = [[0.0, 0.0, 0.3], [1.0, 0.0, 0.3], [2.5, 0.0, 0.3]]  # collinear
    t[1] = [[0.0, 0.0, 0.3], [1.0, 0.01, 0.3], [2.5, 0.0, 0.3]]  # ~1 deg angles
    pixels, _ = render_mutual_pixels(R, t, OMNI)
    result = localize_three(pixels, OMNI, 1.0)
    assert result.status.tolist() == [STATUS_DEGENERATE, STATUS_DEGENERATE, STATUS_OK]
    assert (
        np.isnan(result.R[:2]).all()
        and np.isnan(result.t[:2]).all()
        and np.isfinite(result.t[2]).all()
    )
    assert result.condition[0] > 1e6 and result.condition[2] < 10
    with pytest.raises(ValueError, match="degenerate_triangle"):
        result.relative(0, 1, 2)
    assert "degenerate_triangle" in result.explain(1)


def test_nan_pixel_and_mislabelled_robots():
    rng = np.random.default_rng(15)
    R, t = random_formations(3, rng)
    pixels, _ = render_mutual_pixels(R, t, OMNI)
    pixels[0, 2, 1] = np.nan
    pixels[1, 1, [0, 2]] = pixels[1, 1, [2, 0]]  # robot 2 swaps the labels of robots 1 and 3
    result = localize_three(pixels, OMNI, 2.0)
    assert result.status.tolist() == [STATUS_NO_BEARING, STATUS_INCONSISTENT, STATUS_OK]
    assert np.isnan(result.t[:2]).all() and np.isfinite(result.t[2]).all()
    # a swap keeps the interior angles, so it is the upright test that catches it ...
    assert abs(result.closure[1]) < 1e-9
    # ... and a robot allowed to stand upside-down is indistinguishable from a swap
    anything_goes = localize_three(pixels, OMNI, 2.0, MutualConfig(max_relative_tilt=math.pi))
    assert anything_goes.status[1] == STATUS_OK and anything_goes.R[1, 1, 2, 2] < 0
    # a wrong bearing (another object detected as robot 3 by robot 1) breaks the closure
    wrong = pixels.copy()
    wrong[2, 0, 2] += 40.0
    assert localize_three(wrong, OMNI, 2.0).status[2] == STATUS_INCONSISTENT
    outside = pixels.copy()
    outside[2, 0, 1] = [
        0.0,
        0.0,
    ]  # image corner, beyond the mirror rim: lifts, but to a bearing that does not close
    assert localize_three(outside, OMNI, 2.0).status[2] == STATUS_INCONSISTENT


def test_relative_poses_compose_and_gtsam():
    rng = np.random.default_rng(16)
    R, t = random_formations(5, rng, max_tilt=0.3)
    cams = [
        OMNI,
        OMNI,
        ParaboloidOmniCamera.from_fov(480, math.radians(130)),
    ]  # robot 3 has its own camera
    pixels, _ = render_mutual_pixels(R, t, cams)
    result = localize_three(pixels, cams, np.linalg.norm(t[:, 1] - t[:, 0], axis=1))
    assert result.ok.all()
    R23, t23 = result.relative(2, 2, 3)
    R_w2, R_w3 = R[2, 1], R[2, 2]
    np.testing.assert_allclose(R23, R_w2.T @ R_w3, atol=1e-9)
    np.testing.assert_allclose(t23, R_w2.T @ (t[2, 2] - t[2, 1]), atol=1e-9)
    pose = result.pose3(2, 3, 1)
    assert isinstance(pose, gtsam.Pose3)
    np.testing.assert_allclose(pose.translation(), R_w3.T @ (t[2, 0] - t[2, 2]), atol=1e-9)
    np.testing.assert_allclose(
        result.sides[2],
        [
            np.linalg.norm(t[2, 2] - t[2, 1]),
            np.linalg.norm(t[2, 2] - t[2, 0]),
            np.linalg.norm(t[2, 1] - t[2, 0]),
        ],
        rtol=1e-9,
    )


def test_bad_input_is_a_clear_value_error():
    pixels = np.zeros((2, 3, 3, 2))
    with pytest.raises(ValueError, match="pixels"):
        localize_three(np.zeros((3, 3, 2)), OMNI, 1.0)
    with pytest.raises(ValueError, match="baseline_12"):
        localize_three(pixels, OMNI, [1.0, -1.0])
    with pytest.raises(ValueError, match="baseline_12"):
        localize_three(pixels, OMNI, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="baseline_12"):
        localize_three(pixels, OMNI, float("nan"))
    with pytest.raises(ValueError, match="cameras"):
        localize_three(pixels, [OMNI, OMNI], 1.0)
    with pytest.raises(ValueError, match="min_angle"):
        MutualConfig(min_angle=0.0)
    with pytest.raises(ValueError, match="up"):
        MutualConfig(up=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="R_world"):
        render_mutual_pixels(np.zeros((1, 3, 3)), np.zeros((1, 3, 3)), OMNI)
    result = localize_three(np.full((1, 3, 3, 2), np.nan), OMNI, 1.0)
    assert result.status.tolist() == [STATUS_NO_BEARING]
    with pytest.raises(ValueError, match="numbered"):
        localize_three(*_one_ok_formation()).relative(0, 0, 1)


def _one_ok_formation():
    R, t = random_formations(1, np.random.default_rng(17))
    return render_mutual_pixels(R, t, OMNI)[0], OMNI, 1.0


def test_pinhole_cameras_work_when_they_see_each_other():
    """Any camera model with pixel_to_bearing: three wide pinhole cameras facing the centroid."""
    cam = PinholeCamera.from_fov(640, 480, math.radians(120))
    t = np.array([[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.8, 1.5, 0.0]]])
    centroid = t[0].mean(axis=0)
    R = np.empty((1, 3, 3, 3))
    for i in range(3):
        z = centroid - t[0, i]
        z /= np.linalg.norm(z)
        y = np.array([0.0, 0.0, -1.0])
        x = np.cross(y, z)
        R[0, i] = np.column_stack([x, y, z])
    pixels, visible = render_mutual_pixels(R, t, cam)
    assert visible[0][~np.eye(3, dtype=bool)].all()
    result = localize_three(pixels, cam, 2.0, MutualConfig(up=(0.0, -1.0, 0.0)))
    R_true, t_true = truth_in_frame_1(R, t)
    assert (
        result.ok.all()
        and np.abs(result.t - t_true).max() < 1e-9
        and np.abs(result.R - R_true).max() < 1e-9
    )
    planar = localize_three(pixels, cam, 2.0, MutualConfig(up=(0.0, -1.0, 0.0), planar=True))
    assert planar.ok.all() and np.abs(planar.t - t_true).max() < 1e-9
    # with the wrong `up` the cameras (facing each other) look upside-down relative to C1
    assert localize_three(pixels, cam, 2.0).status[0] == STATUS_INCONSISTENT
