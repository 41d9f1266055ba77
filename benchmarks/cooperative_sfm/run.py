"""`run_cooperative_sfm`: every frame through `CooperativeSfm`, the estimates collected."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graphloc.cameras import PinholeCamera
from benchmarks.cooperative_sfm.config import CooperativeSfmConfig
from benchmarks.cooperative_sfm.graph import CooperativeSfm
from graphloc.seams import FrameInput


@dataclass(frozen=True)
class SfmRun:
    """Result of `run_cooperative_sfm`: causal (T,3) positions (each frame's estimate when it
    arrived), final (T,3) positions (smoothed over all frames), history: at frame k the
    (k+1,3) estimate of frames 0..k, landmark ids/points, the number of factors, skipped
    (non-finite) pixels, and the per-frame latencies [s]; active_causal / active_final (T,):
    the circle candidate the max-mixture was linearized at when the frame arrived / at the
    end (-1: no mixture that frame)."""

    causal_positions: np.ndarray
    final_positions: np.ndarray
    history: tuple[np.ndarray, ...]
    landmark_ids: np.ndarray
    landmark_points: np.ndarray
    n_factors: int
    skipped_pixels: int
    latencies: np.ndarray
    active_causal: np.ndarray
    active_final: np.ndarray


def run_cooperative_sfm(
    frames: list[FrameInput],
    camera: PinholeCamera,
    config: CooperativeSfmConfig = CooperativeSfmConfig(),
) -> SfmRun:
    """Feed every frame through `CooperativeSfm` and collect the estimates."""
    sfm = CooperativeSfm(camera, config)
    for frame in frames:
        sfm.add_frame(frame)
    ids, points = sfm.landmarks()
    causal, final = np.full(len(frames), -1), np.full(len(frames), -1)
    for k, c in sfm.causal_active.items():
        causal[k] = c
    for k, c in sfm.active_components().items():
        final[k] = c
    return SfmRun(
        np.array(sfm.online_positions),
        sfm.positions(),
        tuple(sfm.history),
        ids,
        points,
        int(sfm.session.graph.size()),
        sfm.skipped_pixels,
        sfm.session.latencies(),
        causal,
        final,
    )
