"""Camera tables of a graphloc log that need a camera model: a sensor's intrinsics from its
params, `features` rows (KLT tracks, seed 003 II-B) -> `FeatureObservation`s and `ellipses`
rows (a teammate's circular base, seed 003 II eqs. 1-4) -> circle candidate sets through
`graphloc.vision.circle.circle_candidates` (2 candidates each)."""

from __future__ import annotations

from collections import Counter

import gtsam
import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.manifest import MANIFEST
from graphloc.textio import Sink
from graphloc.records import EllipseObservation, FeaturePixel
from graphloc.run import CandidateObservation, FeatureObservation
from graphloc.vision.circle import circle_candidates

NORMAL_SIGMA = 0.03  # [rad] disk-normal noise of one circle candidate (sensor param normal_sigma)
CIRCLE_YAW_SIGMA = 1.0  # [rad] rotation about the normal, unobservable (param circle_yaw_sigma)


def camera_from_params(params: dict, where: str) -> PinholeCamera:
    """A camera sensor's intrinsics (fx, fy, cx, cy, width, height, optional dist)."""
    try:
        return PinholeCamera(
            float(params["fx"]),
            float(params["fy"]),
            float(params["cx"]),
            float(params["cy"]),
            int(params["width"]),
            int(params["height"]),
            tuple(params.get("dist", ())),
        )
    except KeyError as exc:
        raise ValueError(
            f"{where}: camera params need fx, fy, cx, cy, width, height; missing {exc}"
        ) from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: camera params: {exc}") from None


def positive_param(params: dict, name: str, default: float, where: str) -> float:
    """Sensor param `name` (finite >= 0), `default` where the params give none."""
    value = params.get(name, default)
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(
            f"{where}: params field '{name}' must be a number, got {value!r}"
        ) from None
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"{where}: params field '{name}' must be finite >= 0, got {value}")
    return value


def camera_sensor(robots: tuple, ri: int, sensor: str, manifest) -> tuple:
    """Robot ri's camera `sensor`: extrinsics (Pose3), params, PinholeCamera, where named."""
    T_bs, params = robots[ri].sensors[sensor]
    where = f"{manifest.root / MANIFEST}: robot {robots[ri].name!r} sensor {sensor!r}"
    return gtsam.Pose3(T_bs), params, camera_from_params(params, where), where


def feature_observations(
    rows: list[tuple[int, FeaturePixel]], robots: tuple, manifest, d: dict
) -> list:
    """(robot index, FeaturePixel) rows -> FeatureObservations (pixel noise: the camera's
    `pixel_sigma` param, else d['pixel_sigma']; a new track's point prior: the camera's
    `feature_depth` and `feature_depth_sigma` [m] (default 1 m) params, if given)."""
    out = []
    setups: dict = {}
    for ri, rec in rows:
        if (ri, rec.sensor) not in setups:
            E, params, camera, where = camera_sensor(robots, ri, rec.sensor, manifest)
            sigma = positive_param(params, "pixel_sigma", d["pixel_sigma"], where)
            depth = None
            if "feature_depth" in params:
                depth = tuple(
                    positive_param(params, name, 1.0, where)
                    for name in ("feature_depth", "feature_depth_sigma")
                )
            for name, v in (
                ("pixel_sigma", sigma),
                *zip(("feature_depth", "feature_depth_sigma"), depth or ()),
            ):
                if not v > 0:
                    raise ValueError(f"{where}: params field '{name}' must be > 0")
            setups[(ri, rec.sensor)] = (E, camera, sigma, depth)
        E, camera, sigma, depth = setups[(ri, rec.sensor)]
        out.append(
            FeatureObservation(
                rec.time, ri, E, camera, int(rec.track), np.array([rec.u, rec.v]), sigma, depth
            )
        )
    out.sort(key=lambda f: (f.time, f.robot, f.track))
    return out


def single_tracks(rows: list, manifest, sink, where=None) -> list:
    """`features` rows without the ones whose track appears twice in one image (time, robot,
    sensor): which pixel is the track's cannot be told, so each such row is a counted skip
    `duplicate_track` (as a marker seen twice in one image). where(robot index, row): where a
    row is (default: the table's file and line)."""
    counts = Counter((ri, rec.time, rec.sensor, rec.track) for ri, rec in rows)
    if all(n == 1 for n in counts.values()):
        return rows
    kept = []
    for ri, rec in rows:
        if counts[(ri, rec.time, rec.sensor, rec.track)] == 1:
            kept.append((ri, rec))
            continue
        if where is None:
            at = f"{manifest.root / manifest.robots[ri].tables['features']}: line {rec.line}"
        else:
            at = where(ri, rec)
        sink.bad(
            "duplicate_track",
            f"{at}: field 'track': track {rec.track} appears twice in one image (time {rec.time})",
        )
    return kept


def ellipse_observations(
    rows: list[tuple[int, int, EllipseObservation, str]], robots: tuple, manifest, sink: Sink
) -> list:
    """(observer index, target index, EllipseObservation, where) rows -> circle candidate sets
    (CandidateObservation, source 'circle'); the target's `base_radius` gives the scale; an
    ellipse that is no circle's image is counted (reason 'not_a_circle')."""
    out = []
    for ri, ti, rec, where in rows:
        target = robots[ti]
        if target.base_radius is None:
            raise ValueError(
                f"{where}: field 'target': robot {target.name!r} has no 'base_radius' in the "
                f"manifest (an ellipse needs the circle's radius)"
            )
        E, params, camera, swhere = camera_sensor(robots, ri, rec.sensor, manifest)
        normal = positive_param(params, "normal_sigma", NORMAL_SIGMA, swhere)
        yaw = positive_param(params, "circle_yaw_sigma", CIRCLE_YAW_SIGMA, swhere)
        try:
            cs = circle_candidates(
                camera,
                (rec.u0, rec.v0, rec.width, rec.height, rec.angle),
                target.base_radius,
                rec.centre_sigma,
                rec.radius_sigma,
                normal,
                yaw,
                rec.time,
                robots[ri].name,
                target.name,
            )
        except ValueError as exc:
            sink.bad("not_a_circle", f"{where}: fields 'u0 .. radius_sigma': {exc}")
            continue
        out.append(CandidateObservation(rec.time, ri, ti, E, cs))
    return out
