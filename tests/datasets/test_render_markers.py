"""Renderer + marker detection (seed 001 IV-B) on synthetic frames."""

import cv2
import numpy as np
import pytest

from graphloc.cameras import PinholeCamera
from graphloc.vision.markers import MarkerDetectorConfig, detect_markers
from benchmarks.baselines.seed001_target import marker_area_bounds, roi_from_points
from benchmarks.clutter import clutter_backdrop, random_clutter
from graphloc.datasets.render import Occluder, RenderConfig, render_markers

CAM = PinholeCamera.from_fov(752, 480, np.pi / 2)
RADIUS = 0.015  # seed 001 larger target: b = 3 cm


def markers_at(pixels, depths):
    """Camera-frame centres of spheres seen at `pixels` (M,2) at ranges `depths` (M,)."""
    bearings, ok = CAM.pixel_to_bearing(np.asarray(pixels, float))
    assert ok.all()
    return bearings * np.asarray(depths, float)[:, None]


def random_layout(rng, n=4, min_gap=60.0):
    """n pixel positions at least `min_gap` apart, away from the border, ranges 0.6-3 m."""
    while True:
        px = np.column_stack([rng.uniform(40, 712, n), rng.uniform(40, 440, n)])
        d = np.linalg.norm(px[:, None] - px[None], axis=2) + np.eye(n) * 1e9
        if d.min() > min_gap:
            return px, rng.uniform(0.6, 3.0, n)


def match_errors(found, truth):
    """Distance from every true centroid to the nearest detection."""
    return np.linalg.norm(truth[:, None] - found[None], axis=2).min(axis=1)


def test_projected_size_and_centroid_match_geometry():
    """On the optical axis the disc has radius f*tan(asin(r/d)); off axis the visible-area
    centroid is the centre of the sphere's image ellipse, f*(tan(a+b)+tan(a-b))/2."""
    d = 1.0
    cfg = RenderConfig(
        noise_sigma=0.0, blur_sigma=0.0, gradient=0.0, background=0.0, marker_level=200.0
    )
    frame = render_markers(CAM, np.array([[0.0, 0.0, d]]), RADIUS, cfg)
    r_px = CAM.fx * np.tan(np.arcsin(RADIUS / d))
    area = frame.image.astype(float).sum() / 200.0
    assert area == pytest.approx(np.pi * r_px**2, rel=0.02)
    assert frame.radii[0] == pytest.approx(r_px)
    theta = np.deg2rad(35.0)
    c = d * np.array([np.sin(theta), 0.0, np.cos(theta)])
    frame = render_markers(CAM, c[None], RADIUS, cfg)
    beta = np.arcsin(RADIUS / d)
    u_expected = CAM.cx + CAM.fx * 0.5 * (np.tan(theta + beta) + np.tan(theta - beta))
    assert frame.centroids[0, 0] == pytest.approx(u_expected, abs=0.02)
    assert frame.centers[0, 0] == pytest.approx(CAM.cx + CAM.fx * np.tan(theta), abs=1e-9)


@pytest.mark.parametrize("polarity", ["bright", "dark"])
def test_centroid_error_below_0_3_px_at_noise_sigma_2(polarity):
    rng = np.random.default_rng(3)
    levels = {"bright": (50.0, 220.0), "dark": (190.0, 40.0)}[polarity]
    cfg = RenderConfig(background=levels[0], marker_level=levels[1], noise_sigma=2.0)
    det_cfg = MarkerDetectorConfig(polarity=polarity)
    worst, complete = [], 0
    for _ in range(25):
        px, depth = random_layout(rng)
        frame = render_markers(CAM, markers_at(px, depth), RADIUS, cfg, rng)
        det = detect_markers(frame.image, det_cfg)
        assert len(det) + det.shortfall == 4
        if det.status == "ok":
            complete += 1
            worst.append(match_errors(det.points, frame.centroids).max())
    assert complete >= 24
    assert max(worst) < 0.3


def test_colour_markers_yuv():
    rng = np.random.default_rng(4)
    marker_bgr = (40.0, 60.0, 200.0)  # red paint
    yuv = cv2.cvtColor(np.uint8([[marker_bgr]]), cv2.COLOR_BGR2YUV)[0, 0].astype(float)
    cfg = RenderConfig(
        color=True, background=(120.0, 140.0, 130.0), marker_level=marker_bgr, noise_sigma=2.0
    )
    det_cfg = MarkerDetectorConfig(polarity="color", marker_yuv=tuple(yuv))
    for _ in range(10):
        px, depth = random_layout(rng)
        # a bright grey blob of marker size: as bright as the markers, wrong colour
        clutter = random_clutter(
            rng,
            752,
            480,
            6.0,
            (230.0, 230.0, 230.0),
            n=2,
            avoid=px,
            avoid_radius=30,
            kinds=("disc",),
        )
        backdrop = clutter_backdrop(clutter, cfg.background)
        frame = render_markers(CAM, markers_at(px, depth), RADIUS, cfg, rng, backdrop)
        det = detect_markers(frame.image, det_cfg)
        assert det.status == "ok"
        assert match_errors(det.points, frame.centroids).max() < 0.3


def test_clutter_is_rejected():
    """Markers of one target lie at similar ranges; size bounds come from that range (seed IV-B)."""
    rng = np.random.default_rng(5)
    cfg = RenderConfig(noise_sigma=2.0)
    rejected = 0
    for _ in range(10):
        px, _ = random_layout(rng)
        z = rng.uniform(0.7, 2.5)
        depth = z + rng.uniform(-0.15, 0.15, 4)
        min_area, max_area = marker_area_bounds(CAM.fx, RADIUS, depth.min(), depth.max())
        r_px = CAM.fx * RADIUS / depth.max()
        clutter = random_clutter(
            rng, 752, 480, r_px, 220.0, n=8, avoid=px, avoid_radius=4 * r_px + 10
        )
        backdrop = clutter_backdrop(clutter, cfg.background)
        frame = render_markers(CAM, markers_at(px, depth), RADIUS, cfg, rng, backdrop)
        det = detect_markers(
            frame.image, MarkerDetectorConfig(min_area=min_area, max_area=max_area)
        )
        assert det.status == "ok", det
        assert match_errors(det.points, frame.centroids).max() < 0.3
        rejected += sum(det.rejected.values())
    assert rejected > 0


def test_lookalike_far_from_the_others_is_removed():
    rng = np.random.default_rng(6)
    px = np.array([[300.0, 200.0], [360.0, 230.0], [330.0, 290.0], [280.0, 260.0], [700.0, 60.0]])
    pts = markers_at(px, np.full(5, 1.0))
    frame = render_markers(CAM, pts, RADIUS, RenderConfig(), rng)
    det = detect_markers(frame.image)
    assert det.status == "ok" and "remove" in det.steps
    assert match_errors(det.points, frame.centroids[:4]).max() < 0.3


def test_partial_occlusion_and_shortfall():
    rng = np.random.default_rng(7)
    px = np.array([[200.0, 150.0], [420.0, 170.0], [300.0, 330.0], [560.0, 300.0]])
    pts = markers_at(px, np.full(4, 0.8))
    r = CAM.fx * RADIUS / 0.8
    # a dark bar hides the left 40 % of marker 0 (a cut disc is still convex)
    half = Occluder(
        (px[0, 0] - 2 * r, px[0, 1] - 2 * r, px[0, 0] - 0.2 * r, px[0, 1] + 2 * r), 20.0
    )
    frame = render_markers(CAM, pts, RADIUS, RenderConfig(), rng, occluders=(half,))
    assert 0.5 < frame.visible[0] < 0.8
    det = detect_markers(frame.image)
    assert det.status == "ok"
    assert match_errors(det.points, frame.centroids).max() < 0.3
    # marker 3 fully hidden: a shortfall of one, reported
    full = Occluder((px[3, 0] - 2 * r, px[3, 1] - 2 * r, px[3, 0] + 2 * r, px[3, 1] + 2 * r), 20.0)
    frame = render_markers(CAM, pts, RADIUS, RenderConfig(), rng, occluders=(half, full))
    det = detect_markers(frame.image)
    assert (
        frame.visible[3] == 0 and det.status == "shortfall" and det.shortfall == 1 and len(det) == 3
    )
    assert match_errors(det.points, frame.centroids[:3]).max() < 0.3


def test_touching_markers_are_split_by_erosion():
    rng = np.random.default_rng(8)
    r = CAM.fx * RADIUS / 0.7
    px = np.array([[300.0, 200.0], [300.0 + 2 * r + 1.0, 200.0], [450.0, 320.0], [200.0, 350.0]])
    frame = render_markers(
        CAM, markers_at(px, np.full(4, 0.7)), RADIUS, RenderConfig(blur_sigma=1.2), rng
    )
    det = detect_markers(frame.image)
    assert det.status == "ok" and "erosion" in det.steps
    assert match_errors(det.points, frame.centroids).max() < 1.0


def test_dim_marker_outside_the_otsu_window_is_recovered_by_hough():
    """Otsu (F1) keeps the three bright LEDs; the dim one lies outside their F2 window."""
    rng = np.random.default_rng(11)
    px = np.array([[200.0, 150.0], [260.0, 170.0], [230.0, 230.0], [600.0, 380.0]])
    frame = render_markers(
        CAM,
        markers_at(px, np.full(4, 0.8)),
        RADIUS,
        RenderConfig(gradient=0.0),
        rng,
        gains=np.array([1.0, 1.0, 1.0, 0.25]),
    )
    det = detect_markers(frame.image)
    assert det.status == "ok" and "hough" in det.steps
    assert match_errors(det.points, frame.centroids).max() < 0.3
    dim = np.linalg.norm(det.points - frame.centroids[3], axis=1).argmin()
    assert det.scores[dim] <= 0.5  # Hough-recovered blobs are down-weighted
    off = detect_markers(frame.image, MarkerDetectorConfig(hough=False))
    assert off.status == "shortfall" and off.shortfall == 1


def test_roi_and_full_image_fallback():
    rng = np.random.default_rng(9)
    px = np.array([[200.0, 150.0], [260.0, 170.0], [230.0, 230.0], [600.0, 400.0]])
    frame = render_markers(CAM, markers_at(px, np.full(4, 1.2)), RADIUS, RenderConfig(), rng)
    roi = roi_from_points(px, 30, frame.image.shape)
    det = detect_markers(frame.image, roi=roi)
    assert det.status == "ok" and "full_image" not in det.steps and det.roi == roi
    small = roi_from_points(
        px[:3], 30, frame.image.shape
    )  # misses marker 3: retry on the whole image
    det = detect_markers(frame.image, roi=small)
    assert det.status == "ok" and "full_image" in det.steps
    det = detect_markers(frame.image, MarkerDetectorConfig(full_image_fallback=False), roi=small)
    assert det.status == "shortfall" and det.shortfall == 1


def test_empty_frame_reports_full_shortfall():
    frame = render_markers(CAM, np.zeros((0, 3)), RADIUS, RenderConfig(), np.random.default_rng(10))
    det = detect_markers(frame.image)
    assert len(det) == 0 and det.shortfall == 4 and det.status == "shortfall"


def test_bad_inputs_raise_value_error():
    img = np.zeros((480, 752), np.uint8)
    with pytest.raises(ValueError, match="uint8"):
        detect_markers(img.astype(float))
    with pytest.raises(ValueError, match="BGR"):
        detect_markers(img, MarkerDetectorConfig(polarity="color"))
    with pytest.raises(ValueError, match="polarity"):
        MarkerDetectorConfig(polarity="infrared")
    with pytest.raises(ValueError, match="roi"):
        detect_markers(img, roi=(800, 0, 900, 10))
    with pytest.raises(ValueError, match="NaN"):
        render_markers(CAM, np.array([[0.0, np.nan, 1.0]]), RADIUS)
    with pytest.raises(ValueError, match=r"\(M,3\)"):
        render_markers(CAM, np.zeros((4, 2)), RADIUS)
    with pytest.raises(ValueError, match="inside"):
        render_markers(CAM, np.array([[0.0, 0.0, 0.01]]), RADIUS)
    with pytest.raises(ValueError, match="gains"):
        render_markers(CAM, np.array([[0.0, 0.0, 1.0]]), RADIUS, gains=np.array([1.5]))
