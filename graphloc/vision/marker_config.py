"""Configuration and result types of the seed-001 marker blob extraction
(seeds/001_0f8f8dae37ce6b79.txt, section IV-B; the detector is `graphloc.vision.markers`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from typing import Literal
import numpy as np

from graphloc.config_schema import config_dataclass, setting

POLARITIES = ("bright", "dark", "color")


@config_dataclass
class MarkerDetectorConfig:
    """Parameters of the seed-001 blob extraction (pixels and 8-bit grey levels).

    polarity: "bright" (active LEDs, light paint on dark ground), "dark" (dark paint on light
    ground, thresholds computed inversely) or "color" (YUV chroma distance to `marker_yuv`).
    """

    expected: int = setting(4, ge=1)
    polarity: Literal[POLARITIES] = "bright"
    marker_yuv: tuple[float, float, float] = (0.0, 128.0, 128.0)
    uv_scale: float = 3.0  # likeness grey levels lost per unit of UV distance (colour only)
    min_luma: float = 30.0  # colour only: darker pixels are never markers
    min_area: int = setting(4, gt=0.0)
    max_area: int = 20000
    # minor/major axis of the blob's second moments
    min_axis_ratio: float = setting(0.4, ge=0.0, le=1.0)
    min_solidity: float = setting(0.75, ge=0.0, le=1.0)  # area / convex-hull area
    f2_sigmas: float = 4.0  # F2 = mean + f2_sigmas * std of the fitted background Gaussian
    window_margin: int = 6
    merge_factor: float = 1.5  # merge the closest pair if closer than factor * (r_i + r_j)
    erosion_iterations: int = 2  # erode by discs of radius 1, 2, ... at least this many ...
    erosion_radius_fraction: float = 0.6  # ... and up to this fraction of the largest blob radius
    hough: bool = True
    hough_min_radius: int = 2
    hough_max_radius: int = 40
    hough_perfectness: float = 0.5  # param2 of cv2.HOUGH_GRADIENT_ALT
    full_image_fallback: bool = True  # ROI failed -> search the whole image (seed IV-B)

    def __post_init__(self):
        if not 0.0 < self.min_area <= self.max_area:
            raise ValueError(
                f"MarkerDetectorConfig.min_area must be in (0, max_area = {self.max_area:g}], "
                f"got {self.min_area}"
            )


@dataclass(frozen=True)
class MarkerDetections:
    """Detected marker blobs of one frame.

    points: (M,2) sub-pixel centroids (x, y) in full-image pixel coordinates.
    scores: (M,) shape quality in [0,1] (axis ratio x solidity; Hough-recovered blobs x 0.5).
    radii: (M,) equivalent radius sqrt(area/pi) [px]. areas: (M,) pixel counts.
    expected: number of markers asked for. thresholds: (F1, F2) on the marker-likeness image.
    steps: recovery / reduction steps applied, in order ("merge", "remove", "erosion", "hough",
    "full_image"). roi: (x0, y0, x1, y1) searched first, or None for the whole image.
    """

    points: np.ndarray
    scores: np.ndarray
    radii: np.ndarray
    areas: np.ndarray
    expected: int
    thresholds: tuple[float, float]
    steps: tuple[str, ...] = ()
    roi: tuple[int, int, int, int] | None = None
    rejected: dict = field(default_factory=dict, compare=False)

    @property
    def shortfall(self) -> int:
        return max(0, self.expected - len(self.points))

    @property
    def status(self) -> str:
        return "ok" if self.shortfall == 0 else "shortfall"

    def __len__(self) -> int:
        return len(self.points)
