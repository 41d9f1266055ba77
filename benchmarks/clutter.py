"""Distractor blobs for rendered marker frames (`graphloc.datasets.render.render_markers`'s
`backdrop`): what the marker detector must reject (seed 001 Sec. IV-B)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

CLUTTER_KINDS = ("bar", "large", "speck", "crescent", "disc")


@dataclass(frozen=True)
class Clutter:
    """A distractor blob drawn behind the markers: ellipse centre (x, y) [px], semi-axes
    (a, b) [px], angle [deg], grey level or BGR; kind "crescent" has a bite taken out."""

    kind: str
    center: tuple[float, float]
    axes: tuple[float, float]
    angle: float
    level: float | tuple[float, float, float]


def draw_clutter(img: np.ndarray, clutter: tuple[Clutter, ...], background) -> None:
    """Draw clutter blobs into the float image in place (cv2 ellipses)."""
    for c in clutter:
        level = tuple(float(v) for v in np.atleast_1d(c.level))
        center = (int(round(c.center[0])), int(round(c.center[1])))
        if c.kind == "speck":  # a single hot / dead pixel
            cv2.circle(img, center, 0, level, thickness=-1)
            continue
        axes = (max(1, int(round(c.axes[0]))), max(0, int(round(c.axes[1]))))
        cv2.ellipse(img, center, axes, float(c.angle), 0.0, 360.0, level, thickness=-1)
        if c.kind == "crescent":
            bite = (int(round(c.center[0] + 0.35 * c.axes[0])), center[1])
            bg = tuple(float(v) for v in np.atleast_1d(background))
            cv2.circle(img, bite, max(1, int(round(0.9 * c.axes[0]))), bg, thickness=-1)


def random_clutter(
    rng: np.random.Generator,
    width: int,
    height: int,
    marker_radius_px: float,
    level,
    n: int = 6,
    avoid: np.ndarray | None = None,
    avoid_radius: float = 0.0,
    kinds: tuple[str, ...] = ("bar", "large", "speck", "crescent"),
) -> tuple[Clutter, ...]:
    """`n` distractors the detector should reject: thin bars (eccentric), large blobs (too big),
    specks (too small) and crescents (non-convex); kind "disc" is a marker look-alike. Centres
    keep `avoid_radius` px away from the `avoid` points (the true markers)."""
    unknown = set(kinds) - set(CLUTTER_KINDS)
    if unknown:
        raise ValueError(f"random_clutter: unknown kinds {sorted(unknown)}; known {CLUTTER_KINDS}")
    r = max(float(marker_radius_px), 1.5)
    out = []
    tries = 0
    while len(out) < n:
        tries += 1
        if tries > 1000 * max(n, 1):
            raise ValueError(
                f"random_clutter: cannot place {n} blobs {avoid_radius} px away from the markers"
            )
        kind = kinds[len(out) % len(kinds)]
        center = (rng.uniform(0, width), rng.uniform(0, height))
        size = {
            "bar": (4.0 * r, 0.5 * r),
            "large": (12.0 * r, 12.0 * r),
            "speck": (0.5, 0.5),
            "crescent": (max(2.0 * r, 7.0),) * 2,
            "disc": (r, r),
        }[kind]
        reach = max(size)
        if not (reach <= center[0] <= width - reach and reach <= center[1] <= height - reach):
            continue  # wholly inside the image: a cut-off bar could look like a marker
        if avoid is not None and len(avoid):
            gap = np.linalg.norm(np.asarray(avoid, float) - center, axis=1).min()
            if gap < avoid_radius + reach:
                continue
        if any(
            np.hypot(center[0] - c.center[0], center[1] - c.center[1]) < reach + max(c.axes) + 2
            for c in out
        ):
            continue  # distractors do not touch each other
        out.append(Clutter(kind, center, size, float(rng.uniform(0, 180)), level))
    return tuple(out)


def clutter_backdrop(clutter: tuple[Clutter, ...], background):
    """The `render_markers` backdrop that draws `clutter` on `background` (RenderConfig's)."""
    return lambda img: draw_clutter(img, clutter, background)
