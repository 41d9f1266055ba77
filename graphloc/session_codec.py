"""The JSON codec of saved sessions (`graphloc.session.Session.save` / `load`): GTSAM's built-in
factors graphloc uses (`FACTOR_TYPES`), noise models with robust kernels, Values entries and
factor providers such as `graphloc.factors.mixture.MaxMixture`, as plain numbers. Decoding checks
every number and calls GTSAM constructors only: no pickle, no Boost archive (GTSAM's
`deserialize` crashes the interpreter on a corrupted archive). Errors on decode are `BadData`
naming the step, item and field."""

from __future__ import annotations

import math

import gtsam
import numpy as np

from graphloc.datafile import BadData
from graphloc.factors.mixture import MaxMixture

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
_KERNELS = ("Huber", "Cauchy", "Tukey", "GemanMcClure", "DCS", "Welsch", "Fair")
_PROVIDERS = ("max_mixture",)


def _encode_measurement(kind: str, m) -> list:
    if kind == "pose2":
        return [m.x(), m.y(), m.rotation().c(), m.rotation().s()]
    if kind == "rot2":
        return [m.c(), m.s()]
    if kind in ("pose3", "rot3"):
        return np.asarray(m.matrix(), dtype=float).ravel().tolist()
    if kind == "unit3":
        return np.asarray(m.point3(), dtype=float).tolist()
    if kind == "double":
        return [float(m)]
    if kind == "bearing_range_2d":
        return [m.bearing().c(), m.bearing().s(), float(m.range())]
    if kind == "bearing_range_3d":
        return np.asarray(m.bearing().point3(), dtype=float).tolist() + [float(m.range())]
    return np.asarray(m, dtype=float).ravel().tolist()  # vector


_MEASUREMENT_SIZES = {
    "pose2": 4,
    "rot2": 2,
    "pose3": 16,
    "rot3": 9,
    "unit3": 3,
    "double": 1,
    "bearing_range_2d": 3,
    "bearing_range_3d": 4,
}


def _decode_measurement(kind: str, v: list, where: str):
    want = _MEASUREMENT_SIZES.get(kind)
    if (want is not None and len(v) != want) or (want is None and not v):
        raise BadData(f"{where}: a {kind} measurement needs {want or '>= 1'} numbers, got {len(v)}")
    if kind == "pose2":
        return gtsam.Pose2(_rot2(v[2], v[3], where), np.array(v[:2]))
    if kind == "rot2":
        return _rot2(v[0], v[1], where)
    if kind == "pose3":
        T = np.array(v).reshape(4, 4)
        return gtsam.Pose3(_rot3(T[:3, :3], where), T[:3, 3])
    if kind == "rot3":
        return _rot3(np.array(v).reshape(3, 3), where)
    if kind == "unit3":
        return _unit3(v, where)
    if kind == "double":
        return v[0]
    if kind == "bearing_range_2d":
        return _rot2(v[0], v[1], where), _range(v[2], where)
    if kind == "bearing_range_3d":
        return _unit3(v[:3], where), _range(v[3], where)
    return np.array(v)


def _rot2(c: float, s: float, where: str) -> gtsam.Rot2:
    if abs(math.hypot(c, s) - 1.0) > 1e-9:
        raise BadData(f"{where}: rotation (cos, sin) = ({c}, {s}) is not a unit vector")
    return gtsam.Rot2.fromCosSin(c, s)


def _rot3(R: np.ndarray, where: str) -> gtsam.Rot3:
    with np.errstate(all="ignore"):  # entries of 1e300 overflow: not a rotation either way
        ok = np.abs(R @ R.T - np.eye(3)).max() < 1e-9 and np.linalg.det(R) > 0
    if not ok:
        raise BadData(f"{where}: 3x3 matrix is not a rotation")
    return gtsam.Rot3(R)


def _unit3(v, where: str) -> gtsam.Unit3:
    with np.errstate(all="ignore"):
        norm = float(np.linalg.norm(v))
    if not abs(norm - 1.0) <= 1e-9:
        raise BadData(f"{where}: direction {v} is not a unit vector")
    return gtsam.Unit3(np.array(v, dtype=float))


def _range(r: float, where: str) -> float:
    if not r >= 0:
        raise BadData(f"{where}: range {r} is negative")
    return r


def _kernel_parameters(robust, where: str) -> tuple[str, int, float]:
    """(name, reweight scheme, parameter) of an mEstimator. GTSAM's Python API has no getter for
    the parameter, so it is read from the estimator's own archive of this in-memory object and
    checked by rebuilding the estimator and comparing the two archives."""
    name = type(robust).__name__
    if name not in _KERNELS:
        raise ValueError(
            f"{where}: robust kernel {name} cannot be saved (saved kernels: {_KERNELS})"
        )
    archive = robust.serialize()
    tokens = archive.split()
    try:
        scheme, param = int(tokens[8]), float(tokens[9])
        rebuilt = _make_kernel(name, scheme, param).serialize()
    except (IndexError, ValueError, RuntimeError):
        rebuilt = None
    if rebuilt != archive:
        raise ValueError(
            f"{where}: cannot read the parameter of robust kernel {name} from its archive"
        )
    return name, scheme, param


def _make_kernel(name: str, scheme: int, param: float):
    schemes = gtsam.noiseModel.mEstimator.Base.ReweightScheme
    scheme = schemes.Block if scheme else schemes.Scalar
    return getattr(gtsam.noiseModel.mEstimator, name).Create(param, scheme)


def _encode_noise(model, where: str) -> dict:
    nm = gtsam.noiseModel
    if isinstance(model, nm.Robust):
        name, scheme, param = _kernel_parameters(model.robust(), where)
        return {
            "robust": name,
            "scheme": scheme,
            "k": param,
            "base": _encode_noise(model.noise(), where),
        }
    if isinstance(model, nm.Constrained):
        raise ValueError(f"{where}: a Constrained noise model cannot be saved")
    if isinstance(model, nm.Unit):
        return {"unit": model.dim()}
    if isinstance(model, nm.Isotropic):
        return {"isotropic": model.dim(), "sigma": float(model.sigma())}
    if isinstance(model, nm.Diagonal):
        return {"sigmas": np.asarray(model.sigmas(), dtype=float).tolist()}
    if isinstance(model, nm.Gaussian):
        return {"sqrt_information": np.asarray(model.R(), dtype=float).tolist()}
    raise ValueError(f"{where}: noise model {type(model).__name__} cannot be saved")


def _decode_noise(raw, where: str, depth: int = 0):
    nm = gtsam.noiseModel
    if not isinstance(raw, dict) or (depth and "robust" in raw):
        raise BadData(f"{where}: noise model must be an object (robust over a Gaussian model)")
    if "robust" in raw:
        name, scheme, k = raw.get("robust"), raw.get("scheme"), raw.get("k")
        if name not in _KERNELS or scheme not in (0, 1) or not (_is_number(k) and k > 0):
            raise BadData(
                f"{where}: robust kernel must be one of {_KERNELS} with scheme 0/1 and "
                f"k > 0, got {name!r}, {scheme!r}, {k!r}"
            )
        base = _decode_noise(raw.get("base"), where, 1)
        return nm.Robust.Create(_make_kernel(name, scheme, float(k)), base)
    if "unit" in raw:
        return nm.Unit.Create(_dim(raw["unit"], where))
    if "isotropic" in raw:
        sigma = raw.get("sigma")
        if not (_is_number(sigma) and sigma > 0):
            raise BadData(f"{where}: isotropic sigma must be > 0, got {sigma!r}")
        return nm.Isotropic.Sigma(_dim(raw["isotropic"], where), float(sigma))
    if "sigmas" in raw:
        sigmas = _numbers(raw["sigmas"], f"{where}: sigmas")
        if not (1 <= len(sigmas) <= 64 and min(sigmas) > 0):
            raise BadData(f"{where}: need 1 to 64 sigmas > 0, got {sigmas}")
        return nm.Diagonal.Sigmas(np.array(sigmas), False)
    if "sqrt_information" in raw:
        rows = raw["sqrt_information"]
        if not isinstance(rows, list) or not 1 <= len(rows) <= 64:
            raise BadData(f"{where}: sqrt_information must be a list of 1 to 64 rows")
        R = np.array([_numbers(r, f"{where}: sqrt_information") for r in rows], dtype=object)
        if R.ndim != 2 or R.shape[0] != R.shape[1]:
            raise BadData(f"{where}: sqrt_information must be square")
        R = R.astype(float)
        if np.abs(np.tril(R, -1)).max(initial=0.0) != 0 or not (np.diag(R) > 0).all():
            raise BadData(
                f"{where}: sqrt_information must be upper triangular with a positive diagonal"
            )
        return nm.Gaussian.SqrtInformation(R, False)
    raise BadData(f"{where}: unknown noise model {sorted(raw)}")


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
        "measured": _encode_measurement(kind, getattr(f, getter)()),
        "noise": _encode_noise(f.noiseModel(), where),
    }
    if name == "AttitudeFactorPose3":
        out["b_measured"] = _encode_measurement("unit3", f.bMeasured())
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
    if not (isinstance(keys, list) and len(keys) == n_keys and all(_is_key(k) for k in keys)):
        raise BadData(f"{where}: {name} needs {n_keys} keys (integers in [0, 2^64)), got {keys!r}")
    measured = _decode_measurement(kind, _numbers(raw.get("measured"), f"{where}: measured"), where)
    noise = _decode_noise(raw.get("noise"), where)
    try:
        if name == "AttitudeFactorPose3":
            b = _unit3(_numbers(raw.get("b_measured"), f"{where}: b_measured"), where)
            factor = gtsam.AttitudeFactorPose3(keys[0], measured, noise, b)
        elif name == "GenericProjectionFactorCal3_S2":
            if len(measured) != 2:
                raise BadData(
                    f"{where}: {name} needs a 2-vector pixel, got {len(measured)} numbers"
                )
            cal = _numbers(raw.get("calibration"), f"{where}: calibration")
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
            T = np.array(_numbers(raw.get("body_T_sensor"), f"{where}: body_T_sensor"))
            if T.size != 16:
                raise BadData(f"{where}: body_T_sensor needs 16 numbers, got {T.size}")
            T = T.reshape(4, 4)
            _rot3(T[:3, :3], f"{where}: body_T_sensor")
            factor = _make_factor(name, keys, measured, noise, T)
        else:
            factor = _make_factor(name, keys, measured, noise)
    except (RuntimeError, TypeError) as exc:  # e.g. a noise dimension the factor does not have
        raise BadData(f"{where}: GTSAM rejected the {name} ({exc})") from None
    want = {
        "pose2": 3,
        "pose3": 6,
        "rot2": 1,
        "rot3": 3,
        "unit3": 2,
        "double": 1,
        "bearing_range_2d": 2,
        "bearing_range_3d": 3,
    }.get(kind, len(raw["measured"]))
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
        weights = _numbers(raw.get("weights"), f"{where}: weights")
        try:
            return MaxMixture.from_state(components, weights)
        except ValueError as exc:
            raise BadData(f"{where}: {exc}") from None
    return _decode_factor(raw, where)


def encode_values(values: gtsam.Values, where: str) -> list:
    out = []
    for key in values.keys():
        for kind, get in (
            ("pose3", values.atPose3),
            ("pose2", values.atPose2),
            ("rot3", values.atRot3),
            ("rot2", values.atRot2),
            ("vector", values.atVector),
        ):
            try:
                value = get(key)
            except RuntimeError:
                continue
            numbers = _encode_measurement(kind, value)
            if not all(math.isfinite(x) for x in numbers):
                raise ValueError(f"{where}: value {key_name(key)} is not finite")
            out.append([int(key), kind, numbers])
            break
        else:
            raise ValueError(
                f"{where}: value {key_name(key)} has a type that "
                f"cannot be saved (saved: Pose2, Pose3, Rot2, Rot3, vectors, points)"
            )
    return out


def _decode_values(raw, where: str) -> gtsam.Values:
    if not isinstance(raw, list):
        raise BadData(f"{where}: values must be a list")
    values = gtsam.Values()
    for entry in raw:
        if not (
            isinstance(entry, list)
            and len(entry) == 3
            and _is_key(entry[0])
            and entry[1] in ("pose3", "pose2", "rot3", "rot2", "vector")
        ):
            raise BadData(f"{where}: a value must be [key, kind, numbers], got {str(entry)[:80]}")
        key, kind, numbers = entry
        label = f"{where}, value {key_name(key)}"
        if values.exists(key):
            raise BadData(f"{label}: key given twice")
        values.insert(key, _decode_measurement(kind, _numbers(numbers, label), label))
    return values


def decode_step(raw, where: str) -> tuple[float, list, gtsam.Values]:
    if not isinstance(raw, dict):
        raise BadData(f"{where}: must be an object")
    t = raw.get("time")
    if not _is_number(t):
        raise BadData(f"{where}: time must be a finite number, got {t!r}")
    items = raw.get("items")
    if not isinstance(items, list):
        raise BadData(f"{where}: items must be a list")
    decoded = [_decode_item(item, f"{where}, item {j}") for j, item in enumerate(items)]
    return float(t), decoded, _decode_values(raw.get("values"), where)


def _is_key(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and 0 <= x < 2**64


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _numbers(raw, where: str) -> list:
    if not isinstance(raw, list) or not all(_is_number(x) for x in raw) or len(raw) > 4096:
        raise BadData(f"{where}: expected a list of finite numbers, got {str(raw)[:80]}")
    return [float(x) for x in raw]


def _dim(raw, where: str) -> int:
    if not (isinstance(raw, int) and not isinstance(raw, bool) and 1 <= raw <= 64):
        raise BadData(f"{where}: noise dimension must be an integer in [1, 64], got {raw!r}")
    return raw


def key_name(key: int) -> str:
    """GTSAM's name of a key (x0, l3, ...), or the number when GTSAM cannot format it (a
    symbol character that is not text raises UnicodeDecodeError in DefaultKeyFormatter)."""
    try:
        return gtsam.DefaultKeyFormatter(key)
    except UnicodeDecodeError:
        return str(key)
