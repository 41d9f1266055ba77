"""Inter-robot bearing factors between two Pose3 variables, and range factors for scale (seed 000
Sec. II-III: robot i's camera sees robot j's marker; mutual bearings fix the formation up to
scale, the known distance |^2T_1| of Problem 1 fixes the scale). Built-in GTSAM factors where
one fits, else a gtsam.CustomFactor with analytic Jacobians (docs/design_algorithms.md)."""

from __future__ import annotations


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
            return _seen_error(measured, Ti, body_T_camera, Tj.transformFrom(marker))[0]
        H_q = np.zeros((3, 6), order="F")
        q = Tj.transformFrom(marker, H_q, None)
        e, jacobians[0], H_point = _seen_error(measured, Ti, body_T_camera, q, True)
        jacobians[1] = H_point @ H_q
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
            return _seen_error(measured, T, body_T_camera, q)[0]
        e, jacobians[0], jacobians[1] = _seen_error(measured, T, body_T_camera, q, True)
        return e

    return gtsam.CustomFactor(noise, [pose_key, point_key], error)


def _seen_error(measured: gtsam.Unit3, T, body_T_camera, q, jacobians: bool = False):
    """Unit3 error of the bearing to world point q from the camera at T * body_T_camera; with
    `jacobians` also its Jacobians in T and in q (GTSAM's own, chained), else None, None."""
    if not jacobians:
        pc = T.compose(body_T_camera).transformTo(q)
        return measured.errorVector(gtsam.Unit3.FromPoint3(pc)), None, None
    H_cam = np.zeros((6, 6), order="F")
    H_pc_cam = np.zeros((3, 6), order="F")
    H_pc_q = np.zeros((3, 3), order="F")
    H_u = np.zeros((2, 3), order="F")
    H_e = np.zeros((2, 2), order="F")
    cam = T.compose(body_T_camera, H_cam, None)
    pc = cam.transformTo(q, H_pc_cam, H_pc_q)
    e = measured.errorVector(gtsam.Unit3.FromPoint3(pc, H_u), None, H_e)
    H_eu = H_e @ H_u
    return e, H_eu @ H_pc_cam @ H_cam, H_eu @ H_pc_q


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
