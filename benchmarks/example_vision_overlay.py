"""Example (issue 3): one PNG with the vision front-ends' detections and candidate poses.

Panel 1 -- seed 001 (001_0f8f8dae37ce6b79.txt, IV-B/IV-C): a rendered
752x480 frame of the larger four-marker target with clutter and a partial occlusion; detected
blobs, the true blob centroids, and every target hypothesis reprojected (markers + target axes).
Panel 2 -- seed 003 (graphloc.vision.circle): a rendered disc, its rim, the fitted ellipse and
the two circle-pose candidates (normals drawn from the centre).
Panel 3 -- seed 000 (graphloc.vision.mutual): three robots with panoramic cameras localized
from mutual bearings (noisy pixels), estimate vs truth in robot 1's frame (top view).

    .venv/bin/python scripts/example_vision_overlay.py [--out out/vision_overlay.png --seed 0]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import gtsam
import numpy as np

from graphloc.cameras import ParaboloidOmniCamera, PinholeCamera
from benchmarks.seed001 import look_at
from graphloc.plots import plt
from graphloc.vision.circle import circle_pose_from_rim
from benchmarks.seed003_geometry import rim_points_from_mask
from graphloc.vision.markers import MarkerDetectorConfig, detect_markers
from benchmarks.baselines.seed001_target import marker_area_bounds, target_hypotheses
from graphloc.vision.mutual import localize_three
from benchmarks.clutter import clutter_backdrop, random_clutter
from graphloc.datasets.render import (
    Occluder,
    RenderConfig,
    render_circle_rim,
    render_markers,
    render_mutual_pixels,
)
from graphloc.vision.target import LARGE_TARGET, project_markers


def panel_markers(ax, rng):
    cam = PinholeCamera.from_fov(752, 480, np.pi / 2)
    centre = LARGE_TARGET.points.mean(axis=0)
    eye = centre + np.array([0.35, -0.25, 1.1])
    R, t = look_at(eye, centre + [0.05, 0.03, 0.0], 0.6), eye
    X_cam = (LARGE_TARGET.points - t) @ R
    radius = LARGE_TARGET.marker_diameter / 2
    true_px, _ = cam.project(X_cam)
    r_px = cam.fx * radius / np.linalg.norm(X_cam, axis=1).min()
    clutter = random_clutter(
        rng, 752, 480, r_px, 215.0, n=8, avoid=true_px, avoid_radius=6 * r_px + 20
    )
    occluder = Occluder(
        (
            true_px[1, 0] + 0.3 * r_px,
            true_px[1, 1] - 3 * r_px,
            true_px[1, 0] + 4 * r_px,
            true_px[1, 1] + 3 * r_px,
        ),
        25.0,
    )
    config = RenderConfig(background=55.0, marker_level=215.0)
    backdrop = clutter_backdrop(clutter, config.background)
    frame = render_markers(cam, X_cam, radius, config, rng, backdrop, (occluder,))
    min_area, max_area = marker_area_bounds(cam.fx, radius, 0.5, 2.0)
    det = detect_markers(frame.image, MarkerDetectorConfig(min_area=min_area, max_area=max_area))
    ax.imshow(frame.image, cmap="gray", vmin=0, vmax=255)
    ax.scatter(
        *frame.centroids.T, s=60, facecolors="none", edgecolors="lime", label="true blob centroid"
    )
    ax.scatter(
        *det.points.T,
        s=20,
        marker="+",
        color="red",
        label=f"detected ({det.status}, steps {list(det.steps)})",
    )
    title = f"seed 001 (one marker partly occluded): {len(det)} blobs"
    if len(det) >= 3:
        cands = target_hypotheses(det.points, cam, LARGE_TARGET)
        axes_len = 0.08
        for k in np.argsort(cands.scores):
            px, _ = project_markers(cam, LARGE_TARGET, cands.R[k], cands.t[k])
            colour = plt.cm.viridis(cands.scores[k])
            ax.scatter(*px.T, s=110, marker="s", facecolors="none", edgecolors=[colour])
            origin = LARGE_TARGET.points.mean(axis=0)
            ends = origin + axes_len * np.eye(3)
            tgt = type(LARGE_TARGET)(np.vstack([origin, ends]), LARGE_TARGET.marker_diameter)
            ap, _ = project_markers(cam, tgt, cands.R[k], cands.t[k])
            for e, c in zip(ap[1:], ("r", "g", "b")):
                ax.plot([ap[0, 0], e[0]], [ap[0, 1], e[1]], color=c, lw=1.5)
        best = int(np.argmax(cands.scores))
        err = 100 * np.linalg.norm(cands.t[best] - t)
        title += (
            f", {len(cands)} hypotheses, best score {cands.scores[best]:.2f}, "
            f"position error {err:.2f} cm"
        )
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="lower left")
    ax.axis("off")


def panel_circle(ax, rng):
    cam = PinholeCamera.from_fov(640, 480, np.deg2rad(70))
    centre, normal, radius = np.array([0.1, 0.05, 1.2]), np.array([0.2, -0.6, -0.77]), 0.15
    rim_true, _ = render_circle_rim(cam, centre, normal / np.linalg.norm(normal), radius, 400)
    img = np.full((480, 640), 70, np.uint8)
    cv2.fillPoly(img, [np.round(rim_true).astype(np.int32)], 200)
    img = np.clip(img + rng.normal(0, 2.0, img.shape), 0, 255).astype(np.uint8)
    _, mask = cv2.threshold(img, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    rim = rim_points_from_mask(mask)
    cands, _ = circle_pose_from_rim(cam, rim, radius)
    ax.imshow(img, cmap="gray", vmin=0, vmax=255)
    ax.plot(*rim.T, ",", color="yellow")
    for k, colour in zip(range(len(cands)), ("red", "cyan")):
        c, n = cands.t[k], cands.R[k][:, 2]
        pts, _ = cam.project(np.vstack([c, c + 0.15 * n]))
        ax.plot(
            *pts.T,
            color=colour,
            lw=2,
            label=f"candidate {k}: centre err {100 * np.linalg.norm(c - centre):.2f} cm",
        )
    ax.set_title("seed 003: circle pose from its ellipse (2 candidates)", fontsize=9)
    ax.legend(fontsize=7, loc="lower left")
    ax.axis("off")


def panel_mutual(ax, rng):
    cams = ParaboloidOmniCamera.from_fov(512)
    yaw = np.array([0.3, 2.0, -1.8])
    t_world = np.array([[0.0, 0.0, 0.1], [1.6, 0.3, 0.1], [0.6, 1.4, 0.1]])
    R_world = np.array([gtsam.Rot3.Rz(a).matrix() for a in yaw])
    pixels, _ = render_mutual_pixels(R_world[None], t_world[None], cams)
    noisy = pixels + rng.normal(0, 0.5, pixels.shape)
    est = localize_three(noisy, cams, np.linalg.norm(t_world[1] - t_world[0]))
    true_rel = [
        (R_world[0].T @ R_world[j], R_world[0].T @ (t_world[j] - t_world[0])) for j in range(3)
    ]
    for j in range(3):
        Rt, tt = true_rel[j]
        ax.plot(tt[0], tt[1], "o", color="green", ms=9, label="truth" if j == 0 else None)
        ax.arrow(tt[0], tt[1], 0.25 * Rt[0, 0], 0.25 * Rt[1, 0], color="green", width=0.005)
        if est.ok[0]:
            Re, te = est.relative(0, 1, j + 1)
            ax.plot(
                te[0],
                te[1],
                "x",
                color="red",
                ms=9,
                label="estimate (0.5 px noise)" if j == 0 else None,
            )
            ax.arrow(te[0], te[1], 0.25 * Re[0, 0], 0.25 * Re[1, 0], color="red", width=0.003)
    ax.set_aspect("equal")
    ax.set_title(f"seed 000: three robots from mutual bearings ({est.status[0]})", fontsize=9)
    ax.set(xlabel="x in robot 1 frame [m]", ylabel="y [m]")
    ax.legend(fontsize=7)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/vision_overlay.png"))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    fig, axes = plt.subplots(1, 3, figsize=(18, 5), gridspec_kw={"width_ratios": [1.6, 1.3, 1.0]})
    panel_markers(axes[0], rng)
    panel_circle(axes[1], rng)
    panel_mutual(axes[2], rng)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0
