import math

import cv2
import numpy as np
import pytest

from graphloc.cameras import ParaboloidOmniCamera, PinholeCamera, check_rows, normalize_rows

RNG = np.random.default_rng(7)


def random_bearings(n, max_polar, min_polar=0.0, rng=RNG):
    """Directions uniform on the sphere cap min_polar <= angle from +z <= max_polar."""
    cos_t = rng.uniform(math.cos(max_polar), math.cos(min_polar), n)
    phi = rng.uniform(-math.pi, math.pi, n)
    sin_t = np.sqrt(1.0 - cos_t**2)
    return np.column_stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t])


# ---------------------------------------------------------------- pinhole


@pytest.mark.parametrize("dist", [(), (-0.05, 0.01, 0.001, -0.001), (0.1, -0.02, 5e-4, 3e-4, 1e-3)])
def test_pinhole_pixel_bearing_round_trip(dist):
    cam = PinholeCamera.from_fov(640, 480, 2 * math.pi / 3, dist=dist)  # seed 000 camera C
    pixels = RNG.uniform([-0.5, -0.5], [639.5, 479.5], (2000, 2))
    bearings, valid = cam.pixel_to_bearing(pixels)
    assert valid.all()
    np.testing.assert_allclose(np.linalg.norm(bearings, axis=1), 1.0, atol=1e-12)
    back, visible = cam.bearing_to_pixel(bearings)
    assert visible.all()
    np.testing.assert_allclose(back, pixels, atol=1e-8)


def test_pinhole_matches_opencv_project_points():
    cam = PinholeCamera(500.0, 510.0, 370.0, 245.0, 752, 480, (-0.1, 0.02, 0.001, 0.002, -0.001))
    points = np.column_stack([RNG.uniform(-1, 1, (50, 2)), RNG.uniform(1, 5, 50)])
    rvec, tvec = np.zeros(3), np.zeros(3)
    expected = cv2.projectPoints(points, rvec, tvec, cam.K, np.array(cam.dist))[0].reshape(-1, 2)
    pixels, _ = cam.project(points)
    np.testing.assert_allclose(pixels, expected, atol=1e-9)
    # and the no-distortion closed form equals K x / z
    plain = PinholeCamera(500.0, 510.0, 370.0, 245.0, 752, 480)
    pixels, _ = plain.project(points)
    np.testing.assert_allclose(pixels, (points @ plain.K.T)[:, :2] / points[:, 2:], atol=1e-9)


def test_pinhole_from_fov_seed_settings():
    cam = PinholeCamera.from_fov(752, 480, math.pi / 2)  # seed 001, 90 deg
    assert cam.fx == pytest.approx(376.0)
    # the left and right image borders are at +-45 deg
    pixels, visible = cam.bearing_to_pixel(np.array([[1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]]))
    np.testing.assert_allclose(pixels[:, 0], [375.5 + 376.0, 375.5 - 376.0])


def test_pinhole_visibility_mask():
    cam = PinholeCamera.from_fov(640, 480, math.pi / 2)
    points = np.array(
        [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [5.0, 0.0, 1.0], [np.nan, 0.0, 1.0], [0.0, 0.0, 0.0]]
    )
    pixels, visible = cam.project(points)
    assert visible.tolist() == [True, False, False, False, False]
    assert np.isnan(pixels[[1, 3, 4]]).all() and np.isfinite(pixels[[0, 2]]).all()


def test_pinhole_distortion_fold_is_not_visible():
    """r_d = r (1 + 0.1 r^2 - 0.02 r^4) peaks at r = sqrt(5); a point at r = 3 would fold back
    to r_d = 0.84, i.e. into the image, under cv2.projectPoints."""
    cam = PinholeCamera.from_fov(640, 480, 2 * math.pi / 3, dist=(0.1, -0.02, 0.0, 0.0))
    assert cam.max_radius == pytest.approx(math.sqrt(5.0), rel=1e-3)
    folded = np.array([[3.0, 0.0, 1.0], [1.5, 0.0, 1.0]])
    raw = cv2.projectPoints(folded, np.zeros(3), np.zeros(3), cam.K, np.array(cam.dist))[0].reshape(
        -1, 2
    )
    assert 0 <= raw[0, 0] < cam.width  # what OpenCV alone would claim
    pixels, visible = cam.project(folded)
    assert visible.tolist() == [False, True] and np.isnan(pixels[0]).all()
    beyond = np.array([[cam.cx + 2.3 * cam.fx, cam.cy]])  # distorted radius 2.3 > max 2.236
    assert not cam.pixel_to_bearing(beyond)[1][0]
    assert PinholeCamera.from_fov(640, 480, 1.0).max_radius == math.inf


def test_pinhole_nan_rows_masked_not_crashing():
    cam = PinholeCamera.from_fov(640, 480, 1.2, dist=(-0.05, 0.01, 0.0, 0.0))
    pixels = np.array([[100.0, 100.0], [np.nan, 3.0], [np.inf, 1.0]])
    bearings, valid = cam.pixel_to_bearing(pixels)
    assert valid.tolist() == [True, False, False]
    assert np.isfinite(bearings[0]).all() and np.isnan(bearings[1:]).all()
    empty, valid = cam.pixel_to_bearing(np.zeros((0, 2)))
    assert empty.shape == (0, 3) and valid.shape == (0,)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(fx=-1.0), "fx"),
        (dict(width=0), "width"),
        (dict(dist=(0.1, 0.2, 0.3)), "dist"),
        (dict(cy=float("nan")), "cy"),
        (dict(dist=(0.1, np.nan, 0.0, 0.0)), "dist"),
    ],
)
def test_pinhole_bad_parameters(kwargs, match):
    params = dict(fx=500.0, fy=500.0, cx=320.0, cy=240.0, width=640, height=480)
    params.update(kwargs)
    with pytest.raises(ValueError, match=match):
        PinholeCamera(**params)


def test_wrong_shapes_name_the_argument():
    cam = PinholeCamera.from_fov(640, 480, 1.0)
    omni = ParaboloidOmniCamera.from_fov(512)
    for model in (cam, omni):
        with pytest.raises(ValueError, match="pixels"):
            model.pixel_to_bearing(np.zeros((4, 3)))
        with pytest.raises(ValueError, match="bearings"):
            model.bearing_to_pixel(np.zeros(3))
        with pytest.raises(ValueError, match="points_cam"):
            model.project(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="fov"):
        PinholeCamera.from_fov(640, 480, math.pi)
    with pytest.raises(ValueError, match="points"):
        check_rows([["a", "b"]], 2, "points")


# ------------------------------------------------------- paraboloid omni (seed 000 section II)


@pytest.mark.parametrize("conic_constant", [-1.0, -1.5, -3.0])
def test_omni_bearing_pixel_bearing_round_trip(conic_constant):
    cam = ParaboloidOmniCamera.from_fov(
        512, max_polar_angle=math.radians(115), conic_constant=conic_constant
    )
    bearings = random_bearings(5000, cam.max_polar_angle)
    pixels, visible = cam.bearing_to_pixel(bearings)
    assert visible.all()
    back, valid = cam.pixel_to_bearing(pixels)
    assert valid.all()
    assert np.abs(back - bearings).max() < 1e-9


def test_omni_pixel_bearing_pixel_round_trip():
    cam = ParaboloidOmniCamera.from_fov(512, max_polar_angle=math.radians(110))
    pixels = RNG.uniform(-0.5, 511.5, (5000, 2))
    bearings, valid = cam.pixel_to_bearing(pixels)
    np.testing.assert_allclose(np.linalg.norm(bearings, axis=1), 1.0, atol=1e-12)
    assert valid.all()  # every measured pixel lifts (as for the pinhole) ...
    back, visible = cam.bearing_to_pixel(bearings)
    assert np.abs(back - pixels).max() < 1e-9
    # ... while visibility (projection) is the FOV: the disc of radius size/2 around the centre
    radius = np.linalg.norm(pixels - (cam.cx, cam.cy), axis=1)
    assert (visible == (radius <= 256.0 + 1e-9)).all()


def test_omni_paraboloid_is_para_catadioptric():
    """k = -1: the mirror z = (h^2 - r^2)/(2h) (focus at 0) seen orthographically with
    magnification m gives u - c_x = m * x_mirror, with focal = h * m."""
    h, m = 0.02, 8000.0  # 2 cm mirror parameter, 8000 px/m
    cam = ParaboloidOmniCamera(focal=h * m, size=512, max_polar_angle=math.radians(120))
    d = random_bearings(200, cam.max_polar_angle)
    lam = h / (1.0 + d[:, 2])  # distance from the focus to the mirror along d
    mirror = lam[:, None] * d
    np.testing.assert_allclose(
        mirror[:, 2], (h**2 - mirror[:, 0] ** 2 - mirror[:, 1] ** 2) / (2 * h), atol=1e-15
    )
    pixels, _ = cam.bearing_to_pixel(d)
    np.testing.assert_allclose(pixels - (cam.cx, cam.cy), m * mirror[:, :2], atol=1e-9)
    assert cam.xi == 1.0
    # the horizon is the circle of radius `focal`
    horizon, _ = cam.bearing_to_pixel(np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]))
    np.testing.assert_allclose(np.linalg.norm(horizon - (cam.cx, cam.cy), axis=1), h * m)


def test_omni_fov_and_nan_masks():
    cam = ParaboloidOmniCamera.from_fov(
        512, max_polar_angle=math.radians(100), min_polar_angle=math.radians(10)
    )
    d = np.array(
        [
            [0.0, 0.0, 1.0],  # inside the central blind spot
            [1.0, 0.0, 0.0],  # horizon: visible
            [1.0, 0.0, -1.0],  # 135 deg: outside the FOV
            [0.0, 0.0, -1.0],  # straight down: no image at all
            [np.nan, 0.0, 1.0],
            [0.0, 0.0, 0.0],
        ]
    )
    pixels, visible = cam.bearing_to_pixel(d)
    assert visible.tolist() == [False, True, False, False, False, False]
    assert np.isfinite(pixels[:3]).all() and np.isnan(pixels[3:]).all()
    bearings, valid = cam.pixel_to_bearing(np.array([[np.nan, 1.0], [cam.cx + 50.0, cam.cy]]))
    assert valid.tolist() == [False, True] and np.isnan(bearings[0]).all()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(focal=0.0), "focal"),
        (dict(size=-5), "size"),
        (dict(conic_constant=-0.5), "conic_constant"),
        (dict(max_polar_angle=4.0), "max_polar_angle"),
        (dict(min_polar_angle=2.0, max_polar_angle=1.0), "polar"),
    ],
)
def test_omni_bad_parameters(kwargs, match):
    params = dict(focal=150.0, size=512)
    params.update(kwargs)
    with pytest.raises(ValueError, match=match):
        ParaboloidOmniCamera(**params)


def test_normalize_rows_zero_and_nan():
    out = normalize_rows(np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0], [np.nan, 1.0, 1.0]]))
    np.testing.assert_allclose(out[0], [0.6, 0.8, 0.0])
    assert np.isnan(out[1:]).all()
