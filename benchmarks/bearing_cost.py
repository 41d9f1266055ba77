"""The cost per linearization of graphloc's bearing factors (graphloc.factors.bearing) against
GTSAM's C++ BearingFactor3D, and the noise-free bearing they are measured on."""

from __future__ import annotations

import time

import gtsam
import numpy as np

from graphloc.factors.bearing import bearing_factor, sensor_tie_factor


def predicted_bearing(
    observer: gtsam.Pose3,
    observed: gtsam.Pose3,
    body_T_camera: gtsam.Pose3 = gtsam.Pose3(),
    marker=np.zeros(3),
) -> np.ndarray:
    """Unit bearing (3,) of `observed`'s marker in the camera of `observer` (no noise)."""
    p = observer.compose(body_T_camera).transformTo(
        observed.transformFrom(np.asarray(marker, dtype=float))
    )
    return p / np.linalg.norm(p)


def bearing_linearize_cost(repeats: int = 2000) -> dict:
    """Seconds per linearization of `bearing_factor` with a camera offset (Python CustomFactor,
    Pose3 -> Pose3), of `bearing_factor` with a rotation-only camera (GTSAM's
    BearingRangeFactorPose3), of the built-in route for the offset ("sensor_route": the
    bearing from a sensor pose plus its `sensor_tie_factor`, as if every bearing had a sensor
    pose of its own) and of GTSAM's C++ BearingFactor3D (Pose3 -> Point3) on the same
    geometry, and their ratios to BearingFactor3D."""
    ki, kj = gtsam.symbol("x", 0), gtsam.symbol("x", 1)
    Ti = gtsam.Pose3(gtsam.Rot3.Ypr(0.1, -0.2, 0.3), np.array([0.0, 0.0, 3.0]))
    Tj = gtsam.Pose3(gtsam.Rot3.Ypr(0.4, 0.1, -0.1), np.array([1.0, 0.5, 0.2]))
    offset = gtsam.Pose3(gtsam.Rot3.Ypr(0.2, 0.1, -0.3), np.array([0.1, 0.0, 0.05]))
    custom = bearing_factor(ki, kj, predicted_bearing(Ti, Tj, offset), 0.01, offset)
    rotated = bearing_factor(ki, kj, predicted_bearing(Ti, Tj), 0.01)
    builtin = gtsam.BearingFactor3D(
        ki, kj, Ti.bearing(Tj.translation()), gtsam.noiseModel.Isotropic.Sigma(2, 0.01)
    )
    ks = gtsam.symbol("s", 0)
    routed = gtsam.NonlinearFactorGraph()
    routed.add(sensor_tie_factor(ki, ks, offset))
    routed.add(bearing_factor(ks, kj, predicted_bearing(Ti, Tj, offset), 0.01))
    v_custom, v_builtin = gtsam.Values(), gtsam.Values()
    v_custom.insert(ki, Ti)
    v_custom.insert(kj, Tj)
    v_builtin.insert(ki, Ti)
    v_builtin.insert(kj, Tj.translation())
    v_routed = gtsam.Values(v_custom)
    v_routed.insert(ks, Ti.compose(offset))
    out = {}
    for name, factor, values in (
        ("custom", custom, v_custom),
        ("rotation_only", rotated, v_custom),
        ("sensor_route", routed, v_routed),
        ("builtin", builtin, v_builtin),
    ):
        t0 = time.perf_counter()
        for _ in range(repeats):
            factor.linearize(values)
        out[f"{name}_s"] = (time.perf_counter() - t0) / repeats
    out["ratio"] = out["custom_s"] / out["builtin_s"]
    out["rotation_only_ratio"] = out["rotation_only_s"] / out["builtin_s"]
    out["sensor_route_ratio"] = out["sensor_route_s"] / out["builtin_s"]
    return out
