"""The JSON codec of saved sessions: GTSAM's built-in factors graphloc uses and factor providers
(`MaxMixture`), rebuilt from checked numbers by GTSAM constructors only (no pickle, no Boost
archive); decode errors are `BadData` naming the step, item and field."""

from __future__ import annotations

from dataclasses import asdict

import gtsam
import numpy as np

from graphloc.datafile import BadData, read_data_file, write_data_file
from graphloc.session_config import config_from_dict
from graphloc.factors.mixture import MaxMixture
from graphloc.value_codec import (
    KINDS,
    checked_numbers,
    decode_measurement,
    decode_noise,
    decode_rot3,
    decode_unit3,
    decode_values,
    encode_measurement,
    encode_noise,
    encode_values,
    is_key,
    is_number,
)

# measurement kinds: how a factor's measurement is written and rebuilt
_FACTOR_TYPES = {
    **{
        f"PriorFactor{t}": ("prior", k, 1)
        for t, k in (
            ("Pose2", "pose2"),
            ("Pose3", "pose3"),
            ("Rot2", "rot2"),
            ("Rot3", "rot3"),
            ("Point2", "vector"),
            ("Point3", "vector"),
            ("Unit3", "unit3"),
            ("Double", "double"),
        )
    },
    **{
        f"BetweenFactor{t}": ("measured", k, 2)
        for t, k in (
            ("Pose2", "pose2"),
            ("Pose3", "pose3"),
            ("Rot2", "rot2"),
            ("Rot3", "rot3"),
            ("Point2", "vector"),
            ("Point3", "vector"),
            ("Double", "double"),
        )
    },
    **{
        f"RangeFactor{t}": ("measured", "double", 2)
        for t in ("2", "2D", "3", "3D", "Pose2", "Pose3")
    },
    "RangeFactorWithTransformPose3": ("measured", "double", 2),  # + body_T_sensor
    "BearingFactor2D": ("measured", "rot2", 2),
    "BearingFactorPose2": ("measured", "rot2", 2),
    "BearingFactor3D": ("measured", "unit3", 2),
    "BearingRangeFactor2D": ("measured", "bearing_range_2d", 2),
    "BearingRangeFactorPose2": ("measured", "bearing_range_2d", 2),
    "BearingRangeFactor3D": ("measured", "bearing_range_3d", 2),
    "BearingRangeFactorPose3": ("measured", "bearing_range_3d", 2),
    "AttitudeFactorPose3": ("nRef", "unit3", 1),  # + bMeasured
    "GenericProjectionFactorCal3_S2": ("measured", "vector", 2),  # + calibration, cheirality flags
}


_PROVIDERS = ("max_mixture",)


def _encode_factor(f, where: str) -> dict:
    name = type(f).__name__
    spec = _FACTOR_TYPES.get(name)
    if spec is None:
        raise ValueError(
            f"{where}: factor type {name} cannot be saved (saved types: built-in "
            f"{', '.join(sorted(_FACTOR_TYPES))}, and factor providers {_PROVIDERS})"
        )
    getter, kind, n_keys = spec
    out = {
        "type": name,
        "keys": [int(k) for k in f.keys()],
        "measured": encode_measurement(kind, getattr(f, getter)()),
        "noise": encode_noise(f.noiseModel(), where),
    }
    if name == "AttitudeFactorPose3":
        out["b_measured"] = encode_measurement("unit3", f.bMeasured())
    if name == "GenericProjectionFactorCal3_S2":
        out["calibration"] = np.asarray(f.calibration().vector(), dtype=float).tolist()
        out["cheirality"] = [bool(f.throwCheirality()), bool(f.verboseCheirality())]
        rebuilt = _make_factor(name, out["keys"], f.measured(), f.noiseModel(), out).serialize()
        if rebuilt != f.serialize():  # e.g. a body_P_sensor, which has no getter
            raise ValueError(f"{where}: {name} with a body_P_sensor cannot be saved")
    if name == "RangeFactorWithTransformPose3":  # body_T_sensor has no getter: from the archive
        archive = f.serialize()
        tokens = archive.split()
        try:
            body = np.array([float(x) for x in tokens[-14:-5] + tokens[-3:]])
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = body[:9].reshape(3, 3), body[9:]
            rebuilt = _make_factor(name, out["keys"], f.measured(), f.noiseModel(), T).serialize()
        except (ValueError, RuntimeError):
            rebuilt = None
        if rebuilt != archive:
            raise ValueError(f"{where}: cannot read body_T_sensor of {name} from its archive")
        out["body_T_sensor"] = T.ravel().tolist()
    return out


def _make_factor(name: str, keys: list, measured, noise, extra=None):
    cls = getattr(gtsam, name)
    if name == "GenericProjectionFactorCal3_S2":
        return cls(
            np.asarray(measured),
            noise,
            *keys,
            gtsam.Cal3_S2(*extra["calibration"]),
            *extra["cheirality"],
        )
    if name == "RangeFactorWithTransformPose3":
        T = np.asarray(extra)
        return cls(*keys, measured, noise, gtsam.Pose3(gtsam.Rot3(T[:3, :3]), T[:3, 3]))
    if isinstance(measured, tuple):  # bearing, range
        return cls(*keys, *measured, noise)
    return cls(*keys, measured, noise)


def _decode_factor(raw, where: str):
    if not isinstance(raw, dict):
        raise BadData(f"{where}: a factor must be an object")
    name = raw.get("type")
    spec = _FACTOR_TYPES.get(name) if isinstance(name, str) else None
    if spec is None or not hasattr(gtsam, name):
        raise BadData(f"{where}: unknown factor type {name!r}")
    _, kind, n_keys = spec
    keys = raw.get("keys")
    if not (isinstance(keys, list) and len(keys) == n_keys and all(is_key(k) for k in keys)):
        raise BadData(f"{where}: {name} needs {n_keys} keys (integers in [0, 2^64)), got {keys!r}")
    measured = decode_measurement(
        kind, checked_numbers(raw.get("measured"), f"{where}: measured"), where
    )
    noise = decode_noise(raw.get("noise"), where)
    try:
        if name == "AttitudeFactorPose3":
            b = decode_unit3(checked_numbers(raw.get("b_measured"), f"{where}: b_measured"), where)
            factor = gtsam.AttitudeFactorPose3(keys[0], measured, noise, b)
        elif name == "GenericProjectionFactorCal3_S2":
            if len(measured) != 2:
                raise BadData(
                    f"{where}: {name} needs a 2-vector pixel, got {len(measured)} numbers"
                )
            cal = checked_numbers(raw.get("calibration"), f"{where}: calibration")
            flags = raw.get("cheirality")
            if len(cal) != 5 or not (cal[0] > 0 and cal[1] > 0):
                raise BadData(
                    f"{where}: calibration must be fx, fy, s, u0, v0 with fx, fy > 0, got {cal}"
                )
            if not (
                isinstance(flags, list)
                and len(flags) == 2
                and all(isinstance(b, bool) for b in flags)
            ):
                raise BadData(f"{where}: cheirality must be two booleans, got {flags!r}")
            extra = {"calibration": cal, "cheirality": flags}
            factor = _make_factor(name, keys, measured, noise, extra)
        elif name == "RangeFactorWithTransformPose3":
            T = np.array(checked_numbers(raw.get("body_T_sensor"), f"{where}: body_T_sensor"))
            if T.size != 16:
                raise BadData(f"{where}: body_T_sensor needs 16 numbers, got {T.size}")
            T = T.reshape(4, 4)
            decode_rot3(T[:3, :3], f"{where}: body_T_sensor")
            factor = _make_factor(name, keys, measured, noise, T)
        else:
            factor = _make_factor(name, keys, measured, noise)
    except (RuntimeError, TypeError) as exc:  # e.g. a noise dimension the factor does not have
        raise BadData(f"{where}: GTSAM rejected the {name} ({exc})") from None
    want = KINDS[kind][1] if kind in KINDS else len(raw["measured"])
    if noise.dim() != want:  # a mismatch GTSAM would not notice could corrupt memory
        raise BadData(
            f"{where}: {name} has an error of dimension {want}, its noise model {noise.dim()}"
        )
    return factor


def encode_item(item, where: str) -> dict:
    """One added item: a built-in factor, or a factor provider (an object with `save_state`)."""
    if hasattr(item, "save_state"):
        state = item.save_state()
        return {
            "provider": state["kind"],
            "weights": [float(w) for w in state["weights"]],
            "components": [
                [_encode_factor(f, f"{where}, component {c}") for f in group]
                for c, group in enumerate(state["components"])
            ],
        }
    if hasattr(item, "factor") and not isinstance(item, gtsam.NonlinearFactor):
        raise ValueError(
            f"{where}: factor provider {type(item).__name__} has no save_state(), cannot be saved"
        )
    return _encode_factor(item, where)


def _decode_item(raw, where: str):
    if isinstance(raw, dict) and "provider" in raw:
        if raw["provider"] != "max_mixture":
            raise BadData(
                f"{where}: unknown factor provider {raw['provider']!r} (known: {_PROVIDERS})"
            )
        groups = raw.get("components")
        if not isinstance(groups, list) or not all(isinstance(g, list) for g in groups):
            raise BadData(f"{where}: max_mixture components must be a list of lists of factors")
        components = [
            [_decode_factor(f, f"{where}, component {c}") for f in g] for c, g in enumerate(groups)
        ]
        weights = checked_numbers(raw.get("weights"), f"{where}: weights")
        try:
            return MaxMixture.from_state(components, weights)
        except ValueError as exc:
            raise BadData(f"{where}: {exc}") from None
    return _decode_factor(raw, where)


def decode_step(raw, where: str) -> tuple[float, list, gtsam.Values]:
    if not isinstance(raw, dict):
        raise BadData(f"{where}: must be an object")
    t = raw.get("time")
    if not is_number(t):
        raise BadData(f"{where}: time must be a finite number, got {t!r}")
    items = raw.get("items")
    if not isinstance(items, list):
        raise BadData(f"{where}: items must be a list")
    decoded = [_decode_item(item, f"{where}, item {j}") for j, item in enumerate(items)]
    return float(t), decoded, decode_values(raw.get("values"), where)


def save_session(session, path, fmt: str, version: int) -> None:
    """`Session.save`: config + every step as versioned JSON, atomically; ValueError names the
    step and factor that cannot be written (a bare CustomFactor: add its provider instead)."""
    if not session.config.keep_steps:
        raise ValueError(
            "Session.save: this session keeps no steps (SessionConfig.keep_steps=False: "
            "a long online run that bounds its memory); nothing to replay it from"
        )
    steps = []
    for i, record in enumerate(session._records):
        where = f"Session.save: step {i} (time {record.time})"
        bare = [type(it).__name__ for it in record.items if isinstance(it, gtsam.CustomFactor)]
        if bare:
            raise ValueError(
                f"{where} holds a bare gtsam.CustomFactor, which cannot be "
                f"saved; add its provider object (e.g. MaxMixture) instead"
            )
        items = [encode_item(item, f"{where}, item {j}") for j, item in enumerate(record.items)]
        steps.append(
            {
                "time": record.time,
                "latency_s": record.latency_s,
                "items": items,
                "values": encode_values(record.values, where),
            }
        )
    write_data_file(path, fmt, version, {"config": asdict(session.config), "steps": steps})


def load_session(cls, path, fmt: str, version: int):
    """`Session.load`: a saved session rebuilt as `cls`, every step replayed. Any problem with
    the file (unreadable, not a session, truncated, altered, an unknown factor type, a step the
    session rejects) is a ValueError naming the file."""
    payload = read_data_file(path, fmt, version, "session")
    try:
        session = cls(config_from_dict(payload.get("config")))
        steps = payload.get("steps")
        if not isinstance(steps, list):
            raise BadData("'steps' must be a list")
        for i, step in enumerate(steps):
            t, items, values = decode_step(step, f"step {i}")
            try:
                session.add(items, values, time=t)
            except ValueError as exc:
                raise BadData(f"step {i}: {exc}") from None
    except BadData as exc:
        raise ValueError(f"{path}: {exc}") from None
    return session
