"""Bad input never crashes the vision entry points (issue 17). Property-based (hypothesis, bounded
examples so the file runs in a few seconds; GRAPHLOC_FUZZ_EXAMPLES=2000 for a deeper search):
whatever the marker detector, the base-rim detector and colour score, KLT tracking and corners,
the circle and ellipse fits, the target and mutual-observation front-ends are given, they return
a well-formed result or raise ValueError -- never another exception, a hang or a crash of the
interpreter (OpenCV segfaulted on zero-size images). Plus a corpus of malformed inputs, each with
the exact reason it must give."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from benchmarks.seed003_geometry import rim_points_from_mask
from graphloc.vision.ellipse import fit_ellipse
from graphloc.vision.base_rim import colour_score, detect_base_rim
from graphloc.vision.features import (
    FeatureConfig,
    FeatureTracker,
    detect_corners,
    track_forward_backward,
)
from graphloc.vision.markers import MarkerDetectorConfig, detect_markers
from benchmarks.baselines.seed001_target import roi_from_points
from helpers import FAST

# ---- vision -------------------------------------------------------------------------------------

SIDES = st.integers(0, 24)
IMAGE_SHAPES = st.one_of(
    st.tuples(SIDES, SIDES),
    st.tuples(SIDES, SIDES, st.sampled_from([1, 2, 3, 4])),
    st.tuples(st.integers(0, 3)),
    st.tuples(SIDES, SIDES, st.just(3), st.just(1)),
)
DTYPES = st.sampled_from([np.uint8, np.uint8, np.uint8, np.float32, np.float64, np.int16, bool])


@st.composite
def images(draw, shapes=IMAGE_SHAPES, dtypes=DTYPES):
    """Arbitrary arrays (often not images at all): every shape and dtype above, with content
    from blank to saturated noise and a few bright squares."""
    shape, dtype = draw(shapes), draw(dtypes)
    pixel = st.integers(0, 255) if dtype is np.uint8 else None
    img = draw(hnp.arrays(dtype, shape, elements=pixel, fill=pixel))
    if dtype is np.uint8 and img.ndim >= 2 and img.size:
        for _ in range(draw(st.integers(0, 3))):
            y, x = draw(st.integers(0, img.shape[0] - 1)), draw(st.integers(0, img.shape[1] - 1))
            img[y : y + 4, x : x + 4] = 255
    if draw(st.booleans()) and img.ndim >= 2:
        img = img[::-1]  # negative strides: OpenCV needs a contiguous buffer
    return img


def _valid_image(img, channels=(1, 3)) -> bool:
    return (
        img.dtype == np.uint8
        and min(img.shape[:2] or (0,)) >= 1
        and (
            (img.ndim == 2 and 1 in channels)
            or (img.ndim == 3 and img.shape[2] in channels and img.shape[2] != 1)
        )
    )


@FAST
@given(
    img=images(),
    polarity=st.sampled_from(["bright", "dark", "color"]),
    use_roi=st.booleans(),
    roi=st.tuples(*[st.one_of(st.floats(-50, 80), st.just(np.nan))] * 4),
)
def test_detect_markers_returns_or_raises_value_error(img, polarity, use_roi, roi):
    config = MarkerDetectorConfig(polarity=polarity, expected=2)
    try:
        det = detect_markers(img, config, roi=roi if use_roi else None)
    except ValueError as exc:
        assert str(exc)
        if not _valid_image(img, (3,) if polarity == "color" else (1, 3)):
            return
        assert "roi" in str(exc) and use_roi, exc  # a valid image fails only on a bad roi
        return
    assert _valid_image(img, (3,) if polarity == "color" else (1, 3))
    assert det.points.shape == (len(det), 2) and np.isfinite(det.points).all()
    assert len(det) + det.shortfall >= config.expected and len(det) <= config.expected


@FAST
@given(img=images())
def test_base_rim_and_colour_score_return_or_raise_value_error(img):
    try:
        score = colour_score(img)
    except ValueError:
        assert not _valid_image(img, (3,))
        with pytest.raises(ValueError, match="colour_score: image"):
            detect_base_rim(img)
        return
    assert score.shape == img.shape[:2]
    rim = detect_base_rim(img)
    if rim is not None:
        assert rim.mask.shape == img.shape[:2] and rim.area > 0 and np.isfinite(rim.rim).all()


@FAST
@given(
    a=images(),
    data=st.data(),
    points=hnp.arrays(
        np.float64, st.tuples(st.integers(0, 4), st.just(2)), elements=st.floats(-1e6, 1e6)
    ),
)
def test_klt_entry_points_return_or_raise_value_error(a, data, points):
    b = data.draw(st.one_of(st.just(a[::-1].copy()), images()), label="b")  # often the same shape
    try:
        tracked, ok, fb = track_forward_backward(a, b, points)
    except ValueError:
        assert not (_valid_image(a) and _valid_image(b) and a.shape[:2] == b.shape[:2])
    else:
        assert _valid_image(a) and _valid_image(b)
        assert tracked.shape == points.shape and ok.shape == fb.shape == (len(points),)
    tracker = FeatureTracker(FeatureConfig(max_features=4, border=1))
    for img in (a, b):
        try:
            frame = tracker.step(img)
        except ValueError:
            continue
        assert _valid_image(img) and frame.pixels.shape == (len(frame.ids), 2)
    try:
        corners = detect_corners(a, 3)
    except ValueError:
        assert not _valid_image(a)
    else:
        assert _valid_image(a) and corners.shape[1] == 2 and len(corners) <= 3


@FAST
@given(
    mask=images(dtypes=st.sampled_from([np.uint8, bool, np.float64, np.complex64])),
    points=hnp.arrays(
        np.float64,
        st.tuples(st.integers(0, 8), st.integers(1, 3)),
        elements=st.floats(allow_nan=True, allow_infinity=True),
    ),
)
def test_circle_entry_points_return_or_raise_value_error(mask, points):
    try:
        rim = rim_points_from_mask(mask)
    except ValueError:
        pass
    else:
        assert rim.ndim == 2 and rim.shape[1] == 2 and len(rim) >= 1
    try:
        ellipse = fit_ellipse(points)
    except ValueError:
        pass
    else:
        assert ellipse.shape == (5,)


PIXELS = st.one_of(
    st.floats(-1e4, 1e4), st.sampled_from([0.0, 1e300, -1e300, np.nan, np.inf, 320.0, 240.0])
)


@FAST
@given(
    det=hnp.arrays(np.float64, st.tuples(st.integers(0, 5), st.integers(1, 3)), elements=PIXELS),
    px=hnp.arrays(
        np.float64,
        st.tuples(st.integers(0, 2), st.just(3), st.just(3), st.just(2)),
        elements=PIXELS,
    ),
    baseline=st.one_of(st.floats(allow_nan=True), st.just(1.0)),
)
def test_target_and_mutual_pixels_return_or_raise_value_error(det, px, baseline):
    """The pixel-level front-ends (seed 001 target, seed 000 mutual observation) on arbitrary
    arrays: a CandidateSet / ThreeRobotPoses of finite poses, or a ValueError."""
    from graphloc.cameras import ParaboloidOmniCamera, PinholeCamera
    from graphloc.vision.mutual import localize_three
    from benchmarks.baselines.seed001_target import target_hypotheses

    try:
        cands = target_hypotheses(det, PinholeCamera(500.0, 500.0, 320.0, 240.0, 640, 480))
    except ValueError:
        pass  # what must not happen is any other exception (finite input may still be refused)
    else:
        assert np.isfinite(cands.R).all() and np.isfinite(cands.t).all()
    try:
        poses = localize_three(px, ParaboloidOmniCamera(200.0, 640), baseline)
    except ValueError:
        return
    assert len(poses.R) == len(px)


VISION_CORPUS = [  # (call, the exact reason)
    (
        lambda: detect_markers(np.zeros((0, 0), np.uint8)),
        r"marker image is 0x0 px \(width x height\); at least 1x1 px needed",
    ),
    (lambda: detect_markers(np.zeros((0, 5), np.uint8)), r"marker image is 5x0 px"),
    (lambda: detect_markers(np.zeros((5, 0), np.uint8)), r"marker image is 0x5 px"),
    (lambda: detect_markers(np.zeros((0, 0, 3), np.uint8)), r"marker image is 0x0 px"),
    (
        lambda: detect_base_rim(np.zeros((0, 0, 3), np.uint8)),
        r"colour_score: image \(BGR\) is 0x0 px",
    ),
    (
        lambda: detect_markers(np.zeros((8, 8), np.float32)),
        r"marker image must be an 8-bit image \(dtype uint8\), got dtype float32",
    ),
    (
        lambda: detect_markers(np.zeros((8, 8, 4), np.uint8)),
        r"marker image must have shape \(H,W\) or \(H,W,3\), got \(8, 8, 4\)",
    ),
    (
        lambda: detect_markers(np.zeros((8, 8), np.uint8), MarkerDetectorConfig(polarity="color")),
        r"marker image \(polarity 'color', BGR\) must have shape \(H,W,3\), got \(8, 8\)",
    ),
    (
        lambda: detect_markers(np.zeros((8, 8), np.uint8), roi=(0, 0, np.nan, 5)),
        r"detect_markers: roi \(0, 0, nan, 5\) is not finite",
    ),
    (
        lambda: detect_markers(np.zeros((8, 8), np.uint8), roi="all"),
        r"detect_markers: roi must be 4 numbers",
    ),
    (
        lambda: detect_markers(np.zeros((8, 8), np.uint8), roi=(9, 9, 20, 20)),
        r"detect_markers: roi \(9, 9, 20, 20\) is empty inside the 8x8 image",
    ),
    (
        lambda: detect_markers(np.zeros((8, 8), np.uint8), predicted_px=[1.0, 2.0, np.inf, 0.0]),
        r"detect_markers: predicted_px\[1\] = \[inf  0.\] is not finite",
    ),
    (
        lambda: roi_from_points([[1.0, 2.0]], np.nan, (8, 8)),
        r"roi_from_points: margin must be finite and >= 0, got nan",
    ),
    (
        lambda: track_forward_backward(
            np.zeros((0, 5), np.uint8), np.zeros((0, 5), np.uint8), np.zeros((1, 2))
        ),
        r"prev_gray is 5x0 px",
    ),
    (
        lambda: track_forward_backward(
            np.zeros((5, 5), np.uint8), np.zeros((5, 5), np.uint8), [[np.nan, 1.0]]
        ),
        r"track_forward_backward: points\[0\] = \[nan  1.\] is not finite",
    ),
    (lambda: FeatureTracker().step(np.zeros((4, 0, 3), np.uint8)), r"image is 0x4 px"),
    (
        lambda: colour_score(np.zeros((4, 4), np.uint8)),
        r"colour_score: image \(BGR\) must have shape \(H,W,3\), got \(4, 4\)",
    ),
    (lambda: fit_ellipse(np.zeros((4, 2))), r"fit_ellipse: points has 4 points, at least 5"),
    (lambda: fit_ellipse(np.zeros((6, 2)), "hough"), r"fit_ellipse: method must be one of"),
    (lambda: rim_points_from_mask(np.zeros((0, 4))), r"mask is empty \(shape \(0, 4\)\)"),
    (
        lambda: rim_points_from_mask(np.zeros((4, 4), object)),
        r"mask must be a numeric or boolean image, got dtype object",
    ),
]


@pytest.mark.parametrize("call, reason", VISION_CORPUS)
def test_vision_corpus_gives_the_exact_reason(call, reason):
    with pytest.raises(ValueError, match=reason):
        call()
