"""Entry points of the map fusion pipeline (`graphloc fuse-maps`): `fuse_and_write` (fuse ->
outputs or the "not fused" report) and `fuse_directories` (a user's own scan sequences), with
the user's inputs parsed and checked: the relative pose hint (`--hint`), its 1-sigma
(`--hint-sigma`) and the camera + LED setup of the P3P guess (`--p3p setup.json`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.cameras import PinholeCamera

from graphloc.mapping.io import (
    MAX_COORDINATE,
    POINT_BUDGET,
    check_scan_units,
    read_led_pixels,
    read_scan_sequence,
)
from graphloc.pipelines.map_fusion.fusion import fuse
from graphloc.pipelines.map_fusion.report import write_outputs, write_rejection
from graphloc.pipelines.map_fusion.options import FusionConfig
from graphloc.pipelines.map_fusion.types import FusionInput, FusionRejected, LedObservations
from graphloc.structured import read_json
from graphloc.textio import SkipReport


def fuse_and_write(
    inp: FusionInput, out_dir, config: FusionConfig, times, truth=None, extra=None
) -> dict:
    """fuse -> write_outputs; on FusionRejected write the "not fused" report (no map), attach
    it to the exception as `.report` and re-raise."""
    try:
        result = fuse(inp, config)
    except FusionRejected as exc:
        exc.report = write_rejection(exc, out_dir, truth=truth, extra=extra)
        raise
    return write_outputs(result, out_dir, times, truth=truth, extra=extra)["report"]


def fuse_directories(
    ground_dir,
    ceiling_dir,
    out_dir,
    hint: str | None = None,
    p3p: str | None = None,
    rate: float = 10.0,
    config: FusionConfig = FusionConfig(),
    hint_sigma: str | None = None,
) -> dict:
    """A user's two scan sequences (PCD/PLY/XYZ, file-name order, frame k of both taken together at
    k / rate seconds) + a relative pose hint (with its 1-sigma 'DEG M') or P3P observations ->
    outputs in out_dir. Raises FusionRejected (after writing the "not fused" report)."""
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be a positive frame rate [Hz], got {rate}")
    thinned = SkipReport()  # scans beyond the point budget (graphloc.mapping.io.POINT_BUDGET)
    ground, ground_files, dropped_g = read_scan_sequence(ground_dir, thinned)
    ceiling, ceiling_files, dropped_c = read_scan_sequence(ceiling_dir, thinned)
    if len(ground) != len(ceiling):
        raise ValueError(
            f"{ground_dir} has {len(ground)} scans but {ceiling_dir} has {len(ceiling)}: "
            "the pipeline needs synchronized sequences"
        )
    scales = check_scan_units(
        {"ground": (ground, ground_files), "ceiling": (ceiling, ceiling_files)}
    )
    times = np.arange(len(ground)) / float(rate)
    leds = read_p3p_setup(p3p, len(ground)) if p3p else None
    inp = FusionInput(
        times,
        ground,
        ceiling,
        leds,
        parse_hint(hint) if hint else None,
        parse_hint_sigma(hint_sigma) if hint_sigma else None,
    )
    provenance = {
        "ground": str(ground_dir),
        "ceiling": str(ceiling_dir),
        "frames": len(ground),
        "nonfinite_points_skipped": {"ground": dropped_g, "ceiling": dropped_c},
        "scans_thinned": {"point_budget": POINT_BUDGET, **thinned.as_dict()},
        "scan_scales": scales,
    }
    return fuse_and_write(inp, out_dir, config, times, extra={"input": provenance})


# how far a hand-typed hint's rotation may be off unit length / orthonormal: rounding to two or
# three decimals, far below any hint's sigma
HINT_ROUNDING = 0.01


def parse_hint(text: str) -> np.ndarray:
    """`x y z qx qy qz qw` (TUM order) or 16 numbers (row-major 4x4) -> (4,4) T_G0_C0. A hint
    typed with a few decimals is rounded off a rotation: a quaternion whose norm is within
    HINT_ROUNDING of 1 is normalized, and a 3x3 block within HINT_ROUNDING of orthonormal
    (max |R R^T - I|) becomes its nearest rotation (SciPy's `Rotation.from_matrix`); farther
    off, it is no rotation (a typo) and an error says by how much."""
    try:
        vals = np.array([float(v) for v in text.replace(",", " ").split()])
    except ValueError:
        raise ValueError(f"hint: non-numeric value in {text!r}") from None
    if not np.isfinite(vals).all():
        raise ValueError(f"hint: non-finite value in {text!r}")
    if np.abs(vals).max(initial=0.0) > MAX_COORDINATE:
        raise ValueError(f"hint: values must lie within +-{MAX_COORDINATE:g} (m), got {text!r}")
    if len(vals) == 7:
        q, norm = vals[3:], float(np.linalg.norm(vals[3:]))
        if abs(norm - 1.0) > HINT_ROUNDING:
            raise ValueError(
                f"hint: quaternion {q.tolist()} has norm {norm:.4g}, not unit length (within "
                f"{HINT_ROUNDING}); the order is x y z qx qy qz qw"
            )
        T = np.eye(4)
        # SciPy normalizes the quaternion itself
        T[:3, :3], T[:3, 3] = Rotation.from_quat(q).as_matrix(), vals[:3]
        return T
    if len(vals) == 16:
        T = vals.reshape(4, 4).copy()
        R = T[:3, :3]
        off = float(np.abs(R @ R.T - np.eye(3)).max())
        if not (off <= HINT_ROUNDING and np.allclose(T[3], [0, 0, 0, 1]) and np.linalg.det(R) > 0):
            raise ValueError(
                f"hint: 4x4 matrix is not a rigid transform (max |R R^T - I| = {off:.3g}, "
                f"det R = {np.linalg.det(R):.3g}, last row {T[3].tolist()})"
            )
        T[:3, :3] = Rotation.from_matrix(R).as_matrix()
        return T
    raise ValueError(f"hint: expected 7 (x y z qx qy qz qw) or 16 numbers, got {len(vals)}")


def read_p3p_setup(path, n_frames: int) -> LedObservations:
    """JSON {camera: {fx, fy, cx, cy, width, height[, dist]}, leds: 3x3 (ground LiDAR frame),
    T_ceiling_camera: 4x4, pixels_csv: path relative to the JSON} -> LedObservations."""
    path = Path(path)
    d = read_json(path, what="P3P setup")
    if not isinstance(d, dict):
        raise ValueError(f"{path}: a P3P setup is a JSON object, got {type(d).__name__}")
    if not isinstance(d.get("pixels_csv"), str):
        raise ValueError(f"{path}: field 'pixels_csv' must be the path of the LED pixel CSV")
    try:
        cam = PinholeCamera(**d["camera"])
        leds = np.asarray(d["leds"], dtype=float)
        T = np.asarray(d["T_ceiling_camera"], dtype=float)
        csv_path = path.parent / d["pixels_csv"]
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: malformed P3P setup ({exc})") from None
    if leds.shape != (3, 3) or not np.isfinite(leds).all():
        raise ValueError(f"{path}: leds must be a finite 3x3 array")
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise ValueError(f"{path}: T_ceiling_camera must be a finite 4x4 array")
    return LedObservations(cam, leds, T, read_led_pixels(csv_path, n_frames))


def parse_hint_sigma(text: str) -> tuple[float, float]:
    """`DEG M` (1-sigma rotation [deg] and translation [m] of the hint) -> (rad, m)."""
    try:
        vals = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        raise ValueError(f"hint-sigma: non-numeric value in {text!r}") from None
    if len(vals) != 2 or not all(np.isfinite(v) and v > 0 for v in vals):
        raise ValueError(f"hint-sigma: expected two positive numbers 'DEG M', got {text!r}")
    if vals[0] > 180.0 or vals[1] > MAX_COORDINATE:
        raise ValueError(
            f"hint-sigma: the rotation sigma must be at most 180 deg and the translation sigma "
            f"at most {MAX_COORDINATE:g} m, got {text!r}"
        )
    return float(np.deg2rad(vals[0])), vals[1]
