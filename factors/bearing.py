"""Inter-robot bearing factors between two Pose3 variables, and range / known-baseline factors
for scale (seed 000 Sec. II-III: robot i's camera sees robot j's marker; mutual bearings fix
the formation up to scale, Problem 1 fixes the scale by the known distance |^2T_1|).

`bearing_factor`: robot j's marker (at `marker` in j's body frame) seen by robot i's camera
(`body_T_camera` on i) as a unit bearing in the camera frame; error = Unit3 tangent error
(2-vector) between the measured and the predicted bearing. Where the camera sits at the body
origin and looks at j's origin (a rotation-only `body_T_camera`, no marker offset) it is
GTSAM's built-in BearingRangeFactorPose3 (Pose3 -> Pose3): the bearing rotated into the body
frame (an isotropic bearing noise is the same in any frame) and a range component of std
`UNINFORMATIVE_SIGMA`, which carries no information (its whitened residual is below 1e-6 for
any range under a kilometre). With a camera offset or a marker offset no single built-in fits,
and it is a Python gtsam.CustomFactor with analytic Jacobians chained from GTSAM's own
(Pose3.compose / transformFrom / transformTo, Unit3.FromPoint3 / errorVector).
`bearing_to_point_factor` is the same to a Point3 (GTSAM's BearingFactor3D, else a
CustomFactor).

Built-in route for a camera offset (what the team graph builds, `pipelines.team_graph.points`):
an auxiliary sensor pose variable (`keys.sensor_key`) tied to the body pose by
`sensor_tie_factor` (BetweenFactorPose3 with body_T_camera, std `SENSOR_TIE_SIGMA`), and each
bearing a built-in factor from that sensor pose (the functions above with identity
extrinsics); one sensor pose serves every bearing of its sensor at one time. The tie is soft,
so the estimate differs from the CustomFactor's by a share of order (SENSOR_TIE_SIGMA /
the bearings' positional std)^2; a much tighter tie makes iSAM2's Cholesky indeterminate.
The CustomFactors remain for a marker offset and for callers that hold one factor. The cost
per linearization of each form is measured against BearingFactor3D by
`bearing_linearize_cost`.

`range_factor` / `known_baseline_factor`: gtsam.RangeFactorPose3 (distance between the two
body origins) or gtsam.RangeFactorWithTransformPose3 when the ranging sensor is offset.
"""

from __future__ import annotations

import time

import gtsam
import numpy as np

from graphloc.factors.robust import Kernel, robust_noise


UNINFORMATIVE_SIGMA = 1e6  # std [m] of the built-in bearing's range component: no information


def _unit(bearing, what: str) -> np.ndarray:
    b = np.asarray(bearing, dtype=float)
    if b.shape != (3,) or not np.isfinite(b).all() or np.linalg.norm(b) < 1e-12:
        raise ValueError(f"{what}: bearing must be a finite non-zero 3-vector, got {bearing!r}")
    return b / np.linalg.norm(b)


def _positive(value: float, what: str) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{what} must be finite > 0, got {value}")
    return value


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


def bearing_factor(
    observer_key: int,
    observed_key: int,
    bearing,
    sigma: float,
    body_T_camera: gtsam.Pose3 = gtsam.Pose3(),
    marker=np.zeros(3),
    kernel: Kernel = Kernel(),
) -> gtsam.NoiseModelFactor:
    """Bearing (camera frame of the observer) to the observed robot's marker; isotropic
    `sigma` [rad] on the 2-DOF Unit3 error; optional robust kernel (module docstring: the
    built-in factor where the camera offset and the marker offset are zero)."""
    measured = gtsam.Unit3(_unit(bearing, "bearing_factor"))
    marker = np.asarray(marker, dtype=float)
    if marker.shape != (3,) or not np.isfinite(marker).all():
        raise ValueError(f"bearing_factor: marker must be a finite 3-vector, got {marker!r}")
    if not isinstance(body_T_camera, gtsam.Pose3):
        raise ValueError(
            f"bearing_factor: body_T_camera must be gtsam.Pose3, got {type(body_T_camera).__name__}"
        )
    if observer_key == observed_key:
        raise ValueError("bearing_factor: observer and observed keys must differ")
    sigma = _positive(sigma, "bearing_factor sigma")
    if not marker.any() and not body_T_camera.translation().any():
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([sigma, sigma, UNINFORMATIVE_SIGMA]))
        body = body_T_camera.rotation().rotate(measured.point3())
        return gtsam.BearingRangeFactorPose3(
            observer_key, observed_key, gtsam.Unit3(body), 1.0, robust_noise(noise, kernel)
        )
    noise = robust_noise(gtsam.noiseModel.Isotropic.Sigma(2, sigma), kernel)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians):
        Ti = values.atPose3(this.keys()[0])
        Tj = values.atPose3(this.keys()[1])
        if jacobians is None:
            return measured.errorVector(
                gtsam.Unit3.FromPoint3(
                    Ti.compose(body_T_camera).transformTo(Tj.transformFrom(marker))
                )
            )
        H_cam = np.zeros((6, 6), order="F")
        H_q = np.zeros((3, 6), order="F")
        H_pc_cam = np.zeros((3, 6), order="F")
        H_pc_q = np.zeros((3, 3), order="F")
        H_u = np.zeros((2, 3), order="F")
        H_e = np.zeros((2, 2), order="F")
        cam = Ti.compose(body_T_camera, H_cam, None)
        q = Tj.transformFrom(marker, H_q, None)
        pc = cam.transformTo(q, H_pc_cam, H_pc_q)
        u = gtsam.Unit3.FromPoint3(pc, H_u)
        e = measured.errorVector(u, None, H_e)
        H_eu = H_e @ H_u
        jacobians[0] = H_eu @ H_pc_cam @ H_cam
        jacobians[1] = H_eu @ H_pc_q @ H_q
        return e

    return gtsam.CustomFactor(noise, [observer_key, observed_key], error)


def bearing_to_point_factor(
    pose_key: int,
    point_key: int,
    bearing,
    sigma: float,
    body_T_camera: gtsam.Pose3 = gtsam.Pose3(),
    kernel: Kernel = Kernel(),
) -> gtsam.NoiseModelFactor:
    """Bearing (camera frame of the robot at `pose_key`) to a point variable (a landmark);
    isotropic `sigma` [rad] on the 2-DOF Unit3 error. GTSAM's BearingFactor3D with the bearing
    rotated into the body frame when the camera sits at the body origin; with a camera offset,
    a Python gtsam.CustomFactor chained from GTSAM's own Jacobians (as `bearing_factor`)."""
    measured = gtsam.Unit3(_unit(bearing, "bearing_to_point_factor"))
    sigma = _positive(sigma, "bearing_to_point_factor sigma")
    noise = robust_noise(gtsam.noiseModel.Isotropic.Sigma(2, sigma), kernel)
    if not body_T_camera.translation().any():
        body = body_T_camera.rotation().rotate(measured.point3())
        return gtsam.BearingFactor3D(pose_key, point_key, gtsam.Unit3(body), noise)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians):
        T = values.atPose3(this.keys()[0])
        q = values.atPoint3(this.keys()[1])
        if jacobians is None:
            return measured.errorVector(
                gtsam.Unit3.FromPoint3(T.compose(body_T_camera).transformTo(q))
            )
        H_cam = np.zeros((6, 6), order="F")
        H_pc_cam = np.zeros((3, 6), order="F")
        H_pc_q = np.zeros((3, 3), order="F")
        H_u = np.zeros((2, 3), order="F")
        H_e = np.zeros((2, 2), order="F")
        cam = T.compose(body_T_camera, H_cam, None)
        pc = cam.transformTo(q, H_pc_cam, H_pc_q)
        u = gtsam.Unit3.FromPoint3(pc, H_u)
        e = measured.errorVector(u, None, H_e)
        H_eu = H_e @ H_u
        jacobians[0] = H_eu @ H_pc_cam @ H_cam
        jacobians[1] = H_eu @ H_pc_q
        return e

    return gtsam.CustomFactor(noise, [pose_key, point_key], error)


SENSOR_TIE_SIGMA = 1e-4  # std [rad, m] of the tie of a sensor pose to its body pose


def sensor_tie_factor(
    body_key: int, sensor_key: int, body_T_sensor: gtsam.Pose3, sigma: float = SENSOR_TIE_SIGMA
) -> gtsam.BetweenFactorPose3:
    """The tie of an auxiliary sensor pose variable to its body pose: GTSAM's
    BetweenFactorPose3(body, sensor, body_T_sensor) with isotropic `sigma` on all six tangent
    components (module docstring: the built-in route for offset bearings)."""
    if not isinstance(body_T_sensor, gtsam.Pose3):
        raise ValueError(
            f"sensor_tie_factor: body_T_sensor must be gtsam.Pose3, got "
            f"{type(body_T_sensor).__name__}"
        )
    noise = gtsam.noiseModel.Isotropic.Sigma(6, _positive(sigma, "sensor_tie_factor sigma"))
    return gtsam.BetweenFactorPose3(body_key, sensor_key, body_T_sensor, noise)


def range_factor(
    key_a: int,
    key_b: int,
    distance: float,
    sigma: float,
    body_T_sensor: gtsam.Pose3 | None = None,
    kernel: Kernel = Kernel(),
):
    """Measured distance between two robots: RangeFactorPose3 between the body origins, or
    RangeFactorWithTransformPose3 when the ranging sensor sits at body_T_sensor on robot a."""
    d = _positive(distance, "range_factor distance")
    noise = robust_noise(
        gtsam.noiseModel.Isotropic.Sigma(1, _positive(sigma, "range_factor sigma")), kernel
    )
    if body_T_sensor is None:
        return gtsam.RangeFactorPose3(key_a, key_b, d, noise)
    return gtsam.RangeFactorWithTransformPose3(key_a, key_b, d, noise, body_T_sensor)


def known_baseline_factor(
    key_a: int, key_b: int, baseline: float, sigma: float = 1e-3
) -> gtsam.RangeFactorPose3:
    """Seed 000 Problem 1: the distance |^2T_1| between two robots is known; fixes the scale of
    a bearing-only formation (tight RangeFactorPose3)."""
    return range_factor(key_a, key_b, baseline, sigma)


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
