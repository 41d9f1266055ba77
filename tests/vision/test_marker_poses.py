"""Marker pixels -> candidate sets (`graphloc.vision.marker_poses`): every pixel of a frame judges
every candidate; a candidate no pose explains is refused, a frame none explains is inconsistent."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from graphloc.cameras import PinholeCamera
from graphloc.vision.marker_poses import p3p_candidate_sets

CAMERA = PinholeCamera(420.0, 420.0, 319.5, 239.5, 640, 480)
LAYOUT = np.array(
    [[0.25, 0.15, 0.30], [-0.2, 0.18, 0.34], [-0.05, -0.22, 0.28], [0.18, -0.12, 0.45]]
)


def _frames(n: int, seed: int, sigma: float = 1.0, camera=CAMERA):
    """Camera poses 2-3 m above the layout looking down, the layout's pixels with noise."""
    rng = np.random.default_rng(seed)
    pixels, truth = [], []
    for _ in range(n):
        R_wc = Rotation.from_euler(
            "xyz", [np.pi + rng.normal(0, 0.15), rng.normal(0, 0.15), rng.uniform(-3, 3)]
        ).as_matrix()
        t_wc = np.array([rng.normal(0, 0.3), rng.normal(0, 0.3), rng.uniform(2.0, 3.0)])
        px, _ = camera.project((LAYOUT - t_wc) @ R_wc)
        pixels.append(px + rng.normal(0, sigma, px.shape))
        truth.append((R_wc, t_wc))
    return pixels, truth


def _sets(pixels, truth, markers=4, sigma=1.0, camera=CAMERA):
    ids = [np.arange(markers)] * len(pixels)
    return p3p_candidate_sets(
        camera,
        [p[:markers] for p in pixels],
        ids,
        LAYOUT,
        np.arange(len(pixels), dtype=float),
        sigma,
        truth_t=np.array([t for _, t in truth]),
    )


def test_four_markers_keep_the_candidates_the_pixels_explain_refined_on_all_of_them():
    pixels, truth = _frames(60, seed=1)
    sets = _sets(pixels, truth)
    assert all(s is not None for s in sets)
    # the genuine pose survives the gate (a 99.9 % test: about 1 in 1000 frames may fail it)
    assert sum(s.meta.get("inconsistent", False) for s in sets) <= 1
    kept = [s for s in sets if len(s)]
    assert np.median([s.meta["genuine_error"] for s in kept]) < 0.15  # 1 px at 2-3 m
    # the chi-square of the best candidate behaves like a chi-square with 2 degrees of freedom
    best = np.array([s.meta["chi2"][0] for s in kept])
    assert 1.0 < best.mean() < 3.5 and all(s.meta["dof"] == 2 for s in kept)
    # every candidate left passes the gate; P3P's pseudo solutions on three markers mostly do not
    assert all(np.all(np.array(s.meta["chi2"]) <= s.meta["gate"]) for s in kept)
    assert np.mean([len(s) for s in kept]) < 1.5
    # the covariance comes from all four markers: tighter than three markers' resection
    three = _sets(pixels, truth, markers=3)
    for s4, s3 in zip(kept[:10], three[:10]):
        j = int(np.argmin(np.linalg.norm(s3.t - s4.t[0], axis=1)))
        assert np.trace(s4.covariance[0][3:, 3:]) < np.trace(s3.covariance[j][3:, 3:])


def test_three_markers_cannot_be_judged_and_every_p3p_candidate_stays():
    pixels, truth = _frames(20, seed=2)
    sets = _sets(pixels, truth, markers=3)
    assert all(len(s) >= 1 and "chi2" not in s.meta for s in sets)
    assert np.mean([len(s) for s in sets]) > 1.5  # P3P's ambiguity is left to the tracker


@pytest.mark.parametrize(
    "corrupt",
    ["swap_uv", "fx_20_percent", "layout_permuted"],
)
def test_pixels_no_pose_explains_make_the_set_inconsistent(corrupt):
    pixels, truth = _frames(60, seed=3)
    camera, layout = CAMERA, LAYOUT
    if corrupt == "swap_uv":
        pixels = [p[:, ::-1].copy() for p in pixels]
    elif corrupt == "fx_20_percent":
        camera = PinholeCamera(420.0 * 1.2, 420.0, 319.5, 239.5, 640, 480)
    sets = p3p_candidate_sets(
        camera,
        pixels,
        [np.arange(4)] * len(pixels),
        LAYOUT[[1, 0, 2, 3]] if corrupt == "layout_permuted" else layout,
        np.arange(len(pixels), dtype=float),
        1.0,
    )
    inconsistent = [s for s in sets if s is not None and s.meta.get("inconsistent")]
    assert all(len(s) == 0 and s.meta["chi2_min"] > s.meta["gate"] for s in inconsistent)
    assert len(inconsistent) > 0.3 * len(sets), (corrupt, len(inconsistent))


def test_a_distorted_camera_is_refined_and_judged_through_its_distortion():
    camera = PinholeCamera(420.0, 420.0, 319.5, 239.5, 640, 480, dist=(-0.2, 0.05, 0.0, 0.0))
    pixels, truth = _frames(30, seed=4, camera=camera)
    sets = _sets(pixels, truth, camera=camera)
    kept = [s for s in sets if len(s)]
    assert len(kept) >= 29
    assert np.median([s.meta["genuine_error"] for s in kept]) < 0.15
    assert np.all(np.isfinite(np.stack([s.covariance for s in kept])))
