"""KLT features (Shi-Tomasi + pyramidal LK with forward-backward check) and the base-colour
blob rim (seed 003 II-A-1, II-B-1)."""

import cv2
import numpy as np
import pytest

from graphloc.cameras import PinholeCamera
from graphloc.datasets.textured_scene import disk_coverage
from graphloc.vision.base_rim import BlobConfig, detect_base_rim
from graphloc.vision.features import (
    FeatureConfig,
    FeatureTracker,
    detect_corners,
    track_forward_backward,
)


def textured(h=240, w=320, seed=0):
    rng = np.random.default_rng(seed)
    img = cv2.resize(
        rng.uniform(0, 255, (h // 8, w // 8)).astype(np.float32),
        (w, h),
        interpolation=cv2.INTER_CUBIC,
    )
    for _ in range(40):
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        cv2.rectangle(
            img,
            (x, y),
            (x + int(rng.integers(5, 25)), y + int(rng.integers(5, 25))),
            float(rng.uniform(0, 255)),
            -1,
        )
    return np.clip(img, 0, 255).astype(np.uint8)


def shifted(img, du, dv):
    M = np.float32([[1, 0, du], [0, 1, dv]])
    return cv2.warpAffine(
        img, M, (img.shape[1], img.shape[0]), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT
    )


def test_detect_corners_respects_count_mask_and_border():
    img = textured()
    cfg = FeatureConfig(border=10)
    corners = detect_corners(img, 15, cfg)
    assert 0 < len(corners) <= 15
    mask = np.zeros_like(img)
    mask[:, 160:] = 255
    right = detect_corners(img, 15, cfg, mask)
    assert len(right) > 0 and (right[:, 0] >= 160).all()
    assert (
        (corners >= 10).all()
        and (corners[:, 0] <= 320 - 11).all()
        and (corners[:, 1] <= 240 - 11).all()
    )
    assert detect_corners(img, 0, cfg).shape == (0, 2)


def test_klt_recovers_subpixel_shift():
    img = textured()
    moved = shifted(img, 2.3, -1.6)
    pts = detect_corners(img, 30, FeatureConfig())
    new, ok, fb = track_forward_backward(img, moved, pts)
    assert ok.sum() >= 0.8 * len(pts)
    err = new[ok] - pts[ok] - (2.3, -1.6)
    assert np.median(np.linalg.norm(err, axis=1)) < 0.1
    assert np.isnan(new[~ok]).all()


def test_forward_backward_check_drops_changed_region():
    img = textured(seed=1)
    moved = shifted(img, 1.0, 0.0)
    rng = np.random.default_rng(5)
    moved[:, :120] = rng.uniform(0, 255, moved[:, :120].shape).astype(
        np.uint8
    )  # scene changed on the left
    pts = detect_corners(img, 60, FeatureConfig(min_distance=8))
    _, ok, _ = track_forward_backward(img, moved, pts, FeatureConfig(fb_threshold=0.5))
    left = pts[:, 0] < 100
    assert left.any() and (~left).any()
    assert ok[left].mean() < 0.3 < 0.8 < ok[~left].mean()


def test_tracker_keeps_ids_replenishes_and_honours_exclusion():
    img = textured(seed=2)
    tracker = FeatureTracker(FeatureConfig(max_features=12))
    exclude = np.zeros_like(img)
    exclude[100:140, 140:180] = 255
    f0 = tracker.step(img, exclude)
    assert len(f0.ids) == 12 and f0.n_new == 12
    inside = (
        (f0.pixels[:, 0] >= 140)
        & (f0.pixels[:, 0] < 180)
        & (f0.pixels[:, 1] >= 100)
        & (f0.pixels[:, 1] < 140)
    )
    assert not inside.any()
    f1 = tracker.step(shifted(img, 1.5, 0.5), exclude)
    common = np.intersect1d(f0.ids, f1.ids)
    assert len(common) >= 9 and len(f1.ids) == 12
    a = f0.pixels[np.searchsorted(f0.ids, common)]
    b = f1.pixels[[int(np.flatnonzero(f1.ids == i)[0]) for i in common]]
    assert np.median(np.linalg.norm(b - a - (1.5, 0.5), axis=1)) < 0.15
    # a new view: the old tracks fail the forward-backward check, new ids are started
    f2 = tracker.step(textured(seed=9), exclude)
    assert f2.n_lost > 0 and f2.n_new > 0 and f2.ids.max() > f1.ids.max()


def test_tracker_rejects_bad_input():
    tracker = FeatureTracker()
    with pytest.raises(ValueError, match="uint8"):
        tracker.step(np.zeros((10, 10), np.float32))
    tracker.step(np.zeros((40, 50), np.uint8))
    with pytest.raises(ValueError, match="shape"):
        tracker.step(np.zeros((40, 51), np.uint8))
    with pytest.raises(ValueError, match="exclude"):
        tracker.step(np.zeros((40, 50), np.uint8), np.zeros((4, 5), np.uint8))
    with pytest.raises(ValueError):
        FeatureConfig(quality_level=0.0)


def render_disk(radius_m=0.019, depth=0.8, tilt_deg=25.0, noise=2.0, seed=0):
    cam = PinholeCamera.from_fov(320, 240, np.radians(50))
    c = np.array([0.01, 0.02, depth])
    a = np.radians(tilt_deg)
    n = np.array([np.sin(a), 0.0, -np.cos(a)])
    cov = disk_coverage(cam, c, n, radius_m)
    img = np.full((240, 320, 3), 110.0, np.float32)
    img = img * (1 - cov[..., None]) + np.float32([40, 40, 200]) * cov[..., None]
    img = cv2.GaussianBlur(img, (0, 0), 0.6) + np.random.default_rng(seed).normal(
        0, noise, img.shape
    )
    return cam, c, n, np.clip(np.rint(img), 0, 255).astype(np.uint8)


def test_base_rim_is_subpixel_accurate():
    cam, c, n, img = render_disk()
    blob = detect_base_rim(img)
    assert blob is not None and len(blob.rim) > 40
    # the rim points lie on the true projected circle: compare with the ideal ellipse fit
    from graphloc.datasets.render import render_circle_rim

    truth, _ = render_circle_rim(cam, c, n, 0.019, n_points=720)
    (u0, v0), (w, h), ang = cv2.fitEllipse(truth.astype(np.float32))
    (u1, v1), (w1, h1), ang1 = cv2.fitEllipse(blob.rim.astype(np.float32))
    assert abs(u0 - u1) < 0.05 and abs(v0 - v1) < 0.05
    assert abs(max(w, h) - max(w1, h1)) < 0.1 and abs(min(w, h) - min(w1, h1)) < 0.1
    assert blob.exclusion.sum() > blob.mask.sum()


def test_base_rim_absent_and_bad_image():
    img = np.full((60, 80, 3), 120, np.uint8)
    assert detect_base_rim(img) is None
    with pytest.raises(ValueError, match="BGR"):
        detect_base_rim(np.zeros((60, 80), np.uint8))
    with pytest.raises(ValueError):
        BlobConfig(median_size=4)


def textured_disk(seed, tilt_deg=20.0, depth=0.8, noise=2.0, blur=0.6):
    """The base disk (BGR (40,40,200)) over a grey texture of random brightness with a slight
    green tint -- the case where a threshold on a colour score moves with the texture."""
    cam = PinholeCamera.from_fov(640, 480, np.radians(50))
    rng = np.random.default_rng(seed)
    c = np.array([0.01 + 0.002 * rng.normal(), 0.02, depth])
    a = np.radians(tilt_deg)
    n = np.array([np.sin(a), 0.0, -np.cos(a)])
    cov = disk_coverage(cam, c, n, 0.019)
    grey = cv2.resize(
        rng.uniform(30, 220, (60, 80)).astype(np.float32),
        (640, 480),
        interpolation=cv2.INTER_NEAREST,
    )
    background = grey[..., None] * np.float32([0.95, 1.0, 0.9])
    img = background * (1 - cov[..., None]) + np.float32([40, 40, 200]) * cov[..., None]
    img = cv2.GaussianBlur(img, (0, 0), blur) + rng.normal(0, noise, img.shape)
    return cam, c, n, cov, np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _axes_and_centre(points):
    (u, v), (w, h), _ = cv2.fitEllipse(points.astype(np.float32))
    return np.array([u, v]), np.sort([w, h])


def test_coverage_map_ignores_the_background_brightness():
    from graphloc.vision.base_rim import coverage_map

    _, _, _, cov, img = textured_disk(seed=1, noise=0.0, blur=1e-3)
    blob = detect_base_rim(img, BlobConfig(refine_edges=False))
    alpha, (x0, y0) = coverage_map(img, blob.mask)
    truth = cov[y0 : y0 + alpha.shape[0], x0 : x0 + alpha.shape[1]]
    assert (
        np.abs(alpha - truth).max() < 0.03
    )  # vs up to ~0.15 for a score threshold on this texture
    grey = np.full((60, 80, 3), 120, np.uint8)
    grey[20:40, 30:50] = 200  # a "blob" with the background's own hue
    with pytest.raises(ValueError, match="parallel"):
        coverage_map(grey, (grey[..., 0] == 200).astype(np.uint8))


def test_refined_rim_beats_the_edge_crossings_on_texture():
    """Over 12 textured frames the refined ellipse's axes are within ~0.02 px of the truth
    (rms), about three times closer than the ellipse of the interpolated edge crossings."""
    from graphloc.datasets.render import render_circle_rim

    err_refined, err_crossings, blurs = [], [], []
    for seed in range(12):
        cam, c, n, _, img = textured_disk(seed)
        truth, _ = render_circle_rim(cam, c, n, 0.019, n_points=720)
        centre, axes = _axes_and_centre(truth)
        blob = detect_base_rim(img)
        assert blob.refinement is not None and not blob.refine_error
        blurs.append(blob.refinement.blur)
        for pts, out in ((blob.rim, err_refined), (blob.crossings, err_crossings)):
            c1, a1 = _axes_and_centre(pts)
            out.append(np.abs(a1 - axes).max())
        assert np.linalg.norm(_axes_and_centre(blob.rim)[0] - centre) < 0.02

    def rms(e):
        return float(np.sqrt(np.mean(np.square(e))))

    assert rms(err_refined) < 0.025
    assert rms(err_refined) < 0.6 * rms(err_crossings)
    assert 0.45 < np.median(blurs) < 0.75  # the Gaussian blur of 0.6 px (plus the disk's own edge)
    # its own 1-sigma is of the size of the scatter it shows
    assert 0.001 < blob.refinement.semi_axis_sigma.max() < 0.02


def test_refine_ellipse_errors_are_clear():
    from graphloc.vision.ellipse import refine_ellipse

    with pytest.raises(ValueError, match="pixels within"):
        refine_ellipse(np.zeros((5, 5)), (0, 0), np.array([100.0, 100.0, 30.0, 30.0, 0.0]))
    with pytest.raises(ValueError, match="no edge"):
        refine_ellipse(np.zeros((60, 60)), (0, 0), np.array([30.0, 30.0, 30.0, 28.0, 0.0]))
    with pytest.raises(ValueError, match="finite"):
        refine_ellipse(np.zeros((60, 60)), (0, 0), np.array([30.0, np.nan, 30.0, 28.0, 0.0]))


def test_failed_refinement_is_reported_not_raised(monkeypatch):
    import graphloc.vision.base_rim as base_rim

    def fail(*args, **kwargs):
        raise ValueError("the edge fit diverged (test)")

    monkeypatch.setattr(base_rim, "refine_ellipse", fail)
    _, _, _, _, img = textured_disk(seed=0)
    blob = detect_base_rim(img)
    assert blob.refinement is None and "diverged (test)" in blob.refine_error
    assert blob.exclusion.sum() > 0 and len(blob.crossings) > 40

    from graphloc.vision.teammate import TeammateConfig, measure_frames

    images = np.stack([img, img])
    frames, report = measure_frames(
        images,
        PinholeCamera.from_fov(640, 480, np.radians(50)),
        [0, 1],
        [0, 0],
        [0, 0],
        [0, 0],
        teammate=TeammateConfig(),
    )
    assert report.circle_failed == 2 and all(f.teammate is None for f in frames)
    assert "frame 1: edge refinement failed" in report.circle_reasons[1]
