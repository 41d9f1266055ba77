import math

import cv2
import numpy as np
import pytest

from graphloc.cameras import PinholeCamera
from graphloc.candidates import CandidateSet
from graphloc.vision.circle import (
    CircleConfig,
    circle_pose_from_rim,
    circle_poses_from_rims,
    rotations_from_normals,
)
from graphloc.vision.ellipse import ellipse_to_conic
from benchmarks.seed003_geometry import rim_points_from_mask

from graphloc.datasets.render import render_circle_rim

RADIUS = 0.019  # seed 003: 1.9 cm circle, about 0.83 m from the camera
DISTANCE = 0.83
CAMERA = PinholeCamera.from_fov(640, 480, math.radians(40), dist=(-0.05, 0.01, 0.0005, -0.0005))


def random_circle(rng, max_tilt_deg=60.0):
    """A circle ~0.83 m away, inside the image, normal tilted <= max_tilt from the line of sight."""
    direction = np.array([rng.uniform(-0.15, 0.15), rng.uniform(-0.1, 0.1), 1.0])
    centre = DISTANCE * direction / np.linalg.norm(direction)
    tilt, azim = math.radians(rng.uniform(10.0, max_tilt_deg)), rng.uniform(-math.pi, math.pi)
    toward = -centre / np.linalg.norm(centre)
    R = rotations_from_normals(toward[None])[0]
    normal = R @ np.array(
        [math.sin(tilt) * math.cos(azim), math.sin(tilt) * math.sin(azim), math.cos(tilt)]
    )
    return centre, normal


def best_error(poses, centre, normal, n=0):
    """Centre error [m] and normal error [deg] of the candidate closest to the truth."""
    dc = np.linalg.norm(poses.centres[n] - centre, axis=1)
    dn = np.degrees(np.arccos(np.clip(poses.normals[n] @ normal, -1.0, 1.0)))
    k = int(np.argmin(dn))
    return dc[k], dn[k]


def test_noise_free_one_candidate_exact():
    rng = np.random.default_rng(3)
    for _ in range(20):
        centre, normal = random_circle(rng)
        rim, visible = render_circle_rim(CAMERA, centre, normal, RADIUS, 120)
        assert visible.all()
        candidates, poses = circle_pose_from_rim(
            CAMERA, rim, RADIUS, observer="cam", observed="robot"
        )
        assert isinstance(candidates, CandidateSet) and len(candidates) == 2
        dc, dn = best_error(poses, centre, normal)
        assert dc < 1e-6 and dn < 1e-3
        assert poses.rms_px[0] < 1e-4
        # both candidates: in front, normal towards the camera, orthonormal rotations with
        # z = normal
        assert (candidates.t[:, 2] > 0).all()
        assert (np.einsum("ki,ki->k", poses.normals[0], poses.centres[0]) < 0).all()
        np.testing.assert_allclose(candidates.R[:, :, 2], poses.normals[0], atol=1e-12)
        np.testing.assert_allclose(
            np.einsum("kji,kjl->kil", candidates.R, candidates.R),
            np.tile(np.eye(3), (2, 1, 1)),
            atol=1e-12,
        )
        np.testing.assert_allclose(np.linalg.det(candidates.R), 1.0, atol=1e-12)
        assert candidates.scores[0] == candidates.scores[1] > 0.99
        assert candidates.source == "circle" and candidates.observed == "robot"


def test_frontal_circle_both_solutions_coincide():
    centre = np.array([0.0, 0.0, DISTANCE])
    rim, _ = render_circle_rim(CAMERA, centre, np.array([0.0, 0.0, -1.0]), RADIUS, 64)
    candidates, poses = circle_pose_from_rim(CAMERA, rim, RADIUS)
    np.testing.assert_allclose(poses.centres[0], np.tile(centre, (2, 1)), atol=1e-7)
    np.testing.assert_allclose(poses.normals[0], np.tile([0.0, 0.0, -1.0], (2, 1)), atol=1e-4)
    np.testing.assert_allclose(
        candidates.R[0][:, 0], [1.0, 0.0, 0.0], atol=1e-4
    )  # x = camera x (yaw convention)


def test_the_two_solutions_are_distinct_for_a_tilted_circle():
    rng = np.random.default_rng(4)
    centre, normal = random_circle(rng, max_tilt_deg=50.0)
    rim, _ = render_circle_rim(CAMERA, centre, normal, RADIUS, 100)
    poses = circle_poses_from_rims(CAMERA, [rim], RADIUS)
    angle = np.degrees(np.arccos(np.clip(poses.normals[0, 0] @ poses.normals[0, 1], -1, 1)))
    assert angle > 5.0


def test_pixel_noise_reasonable_error():
    """0.2 px rim noise, 200 points, 1.9 cm circle at 0.83 m (about 30 px radius here)."""
    rng = np.random.default_rng(5)
    centre_errors, normal_errors = [], []
    rims, truths = [], []
    for _ in range(40):
        centre, normal = random_circle(rng, max_tilt_deg=60.0)
        rim, _ = render_circle_rim(CAMERA, centre, normal, RADIUS, 200)
        rims.append(rim + rng.normal(0.0, 0.2, rim.shape))
        truths.append((centre, normal))
    poses = circle_poses_from_rims(CAMERA, np.stack(rims), RADIUS, CircleConfig(pixel_sigma=0.2))
    assert poses.ok.all()
    for n, (centre, normal) in enumerate(truths):
        dc, dn = best_error(poses, centre, normal, n)
        centre_errors.append(dc)
        normal_errors.append(dn)
    assert np.median(centre_errors) < 0.003 * DISTANCE  # 0.3 % of the range (measured ~0.09 %)
    assert np.median(normal_errors) < 1.0  # measured ~0.2 deg
    assert 0.1 < np.median(poses.rms_px) < 0.3  # the residual tracks the injected noise
    scores = np.array([poses.candidates(n).scores[0] for n in range(len(poses))])
    assert (scores > 0.2).all()


def test_rim_from_rendered_mask():
    """Full image path: fill the projected circle into a mask, take its contour, fit."""
    cam = PinholeCamera.from_fov(640, 480, math.radians(40))
    centre, normal = (
        np.array([0.02, -0.01, 0.4]),
        np.array([0.3, 0.2, -1.0]) / np.linalg.norm([0.3, 0.2, -1.0]),
    )
    rim, _ = render_circle_rim(cam, centre, normal, RADIUS, 720)
    mask = np.zeros((cam.height, cam.width), np.uint8)
    cv2.fillPoly(mask, [np.round(rim * 16).astype(np.int32)], 255, lineType=cv2.LINE_8, shift=4)
    boundary = rim_points_from_mask(mask)
    poses = circle_poses_from_rims(cam, [boundary], RADIUS)
    dc, dn = best_error(poses, centre, normal)
    assert dc < 0.01 * np.linalg.norm(centre) and dn < 3.0  # measured ~1 mm, 0.3 deg
    with pytest.raises(ValueError, match="no foreground"):
        rim_points_from_mask(np.zeros((10, 10)))
    with pytest.raises(ValueError, match="2-D"):
        rim_points_from_mask(np.zeros((3, 10, 10)))


def test_nan_rows_are_counted_and_skipped():
    rng = np.random.default_rng(6)
    centre, normal = random_circle(rng)
    rim, _ = render_circle_rim(CAMERA, centre, normal, RADIUS, 60)
    rim[[3, 10, 20]] = np.nan
    candidates, poses = circle_pose_from_rim(CAMERA, rim, RADIUS)
    assert poses.n_skipped[0] == 3 and poses.n_points[0] == 57 and candidates.meta["n_skipped"] == 3
    dc, dn = best_error(poses, centre, normal)
    assert dc < 1e-6


def test_degenerate_rims_reported_not_crashing():
    rng = np.random.default_rng(8)
    centre, normal = random_circle(rng)
    good, _ = render_circle_rim(CAMERA, centre, normal, RADIUS, 50)
    # edge-on: normal perpendicular to the line of sight -> the rim images to a segment
    side = np.cross(centre, [0.0, 1.0, 0.0])
    edge_on, _ = render_circle_rim(CAMERA, centre, side / np.linalg.norm(side), RADIUS, 50)
    nearly_edge_on_normal = side / np.linalg.norm(side) - 0.01 * centre / np.linalg.norm(centre)
    nearly, _ = render_circle_rim(CAMERA, centre, nearly_edge_on_normal, RADIUS, 50)
    few = good[:4]
    all_nan = np.full((30, 2), np.nan)
    poses = circle_poses_from_rims(CAMERA, [good, edge_on, nearly, few, all_nan], RADIUS)
    assert poses.ok.tolist() == [True, False, False, False, False]
    assert poses.status.tolist()[1:] == ["edge_on", "edge_on", "too_few_points", "too_few_points"]
    assert "30 non-finite skipped" in poses.explain(4)
    assert np.isnan(poses.centres[1:]).all() and np.isfinite(poses.centres[0]).all()
    with pytest.raises(ValueError, match="edge_on"):
        circle_pose_from_rim(CAMERA, edge_on, RADIUS)
    with pytest.raises(ValueError, match="rim 3"):
        poses.candidates(3)


def test_bad_arguments():
    rim, _ = render_circle_rim(CAMERA, np.array([0, 0, 0.8]), np.array([0, 0, -1.0]), RADIUS, 20)
    with pytest.raises(ValueError, match="rim"):
        circle_pose_from_rim(CAMERA, rim.T, RADIUS)
    with pytest.raises(ValueError, match=r"rims\[1\]"):
        circle_poses_from_rims(CAMERA, [rim, rim[:, :1]], RADIUS)
    with pytest.raises(ValueError, match="radius"):
        circle_pose_from_rim(CAMERA, rim, -1.0)
    with pytest.raises(ValueError, match="fit"):
        CircleConfig(fit="hough")


@pytest.mark.parametrize("fit", ["direct", "ams", "lsq"])
def test_all_opencv_fitters_agree_noise_free(fit):
    centre, normal = np.array([0.05, 0.02, 0.83]), np.array([0.0, 0.5, -1.0]) / math.sqrt(1.25)
    rim, _ = render_circle_rim(CAMERA, centre, normal, RADIUS, 90)
    poses = circle_poses_from_rims(CAMERA, [rim], RADIUS, CircleConfig(fit=fit))
    dc, dn = best_error(poses, centre, normal)
    assert dc < 1e-6 and dn < 1e-3


def test_ellipse_to_conic_matches_points():
    ellipse = np.array([[100.0, 50.0, 40.0, 20.0, 30.0]])
    C = ellipse_to_conic(ellipse)[0]
    t = np.linspace(0, 2 * np.pi, 20)
    ang = math.radians(30.0)
    pts = np.column_stack(
        [
            100 + 20 * np.cos(t) * math.cos(ang) - 10 * np.sin(t) * math.sin(ang),
            50 + 20 * np.cos(t) * math.sin(ang) + 10 * np.sin(t) * math.cos(ang),
            np.ones(20),
        ]
    )
    np.testing.assert_allclose(np.einsum("ij,jk,ik->i", pts, C, pts), 0.0, atol=1e-12)
    assert np.array([100.0, 50.0, 1.0]) @ C @ np.array([100.0, 50.0, 1.0]) < 0
