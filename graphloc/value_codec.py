"""Checked numbers for GTSAM measurements, Values entries and noise models, the layer under
`graphloc.session_codec`; decode errors are `BadData` naming the field."""

from __future__ import annotations

import math

import gtsam
import numpy as np

from graphloc.datafile import BadData

_KERNELS = ("Huber", "Cauchy", "Tukey", "GemanMcClure", "DCS", "Welsch", "Fair")


def encode_measurement(kind: str, m) -> list:
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


# measurement kind -> (numbers it is written as, dimension of its error); a vector: its length
KINDS = {
    "pose2": (4, 3),
    "rot2": (2, 1),
    "pose3": (16, 6),
    "rot3": (9, 3),
    "unit3": (3, 2),
    "double": (1, 1),
    "bearing_range_2d": (3, 2),
    "bearing_range_3d": (4, 3),
}


def decode_measurement(kind: str, v: list, where: str):
    want = KINDS.get(kind, (None,))[0]
    if (want is not None and len(v) != want) or (want is None and not v):
        raise BadData(f"{where}: a {kind} measurement needs {want or '>= 1'} numbers, got {len(v)}")
    if kind == "pose2":
        return gtsam.Pose2(_rot2(v[2], v[3], where), np.array(v[:2]))
    if kind == "rot2":
        return _rot2(v[0], v[1], where)
    if kind == "pose3":
        T = np.array(v).reshape(4, 4)
        return gtsam.Pose3(decode_rot3(T[:3, :3], where), T[:3, 3])
    if kind == "rot3":
        return decode_rot3(np.array(v).reshape(3, 3), where)
    if kind == "unit3":
        return decode_unit3(v, where)
    if kind == "double":
        return v[0]
    if kind == "bearing_range_2d":
        return _rot2(v[0], v[1], where), _range(v[2], where)
    if kind == "bearing_range_3d":
        return decode_unit3(v[:3], where), _range(v[3], where)
    return np.array(v)


def _rot2(c: float, s: float, where: str) -> gtsam.Rot2:
    if abs(math.hypot(c, s) - 1.0) > 1e-9:
        raise BadData(f"{where}: rotation (cos, sin) = ({c}, {s}) is not a unit vector")
    return gtsam.Rot2.fromCosSin(c, s)


def decode_rot3(R: np.ndarray, where: str) -> gtsam.Rot3:
    with np.errstate(all="ignore"):  # entries of 1e300 overflow: not a rotation either way
        ok = np.abs(R @ R.T - np.eye(3)).max() < 1e-9 and np.linalg.det(R) > 0
    if not ok:
        raise BadData(f"{where}: 3x3 matrix is not a rotation")
    return gtsam.Rot3(R)


def decode_unit3(v, where: str) -> gtsam.Unit3:
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


def encode_noise(model, where: str) -> dict:
    nm = gtsam.noiseModel
    if isinstance(model, nm.Robust):
        name, scheme, param = _kernel_parameters(model.robust(), where)
        return {
            "robust": name,
            "scheme": scheme,
            "k": param,
            "base": encode_noise(model.noise(), where),
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


def decode_noise(raw, where: str, depth: int = 0):
    nm = gtsam.noiseModel
    if not isinstance(raw, dict) or (depth and "robust" in raw):
        raise BadData(f"{where}: noise model must be an object (robust over a Gaussian model)")
    if "robust" in raw:
        name, scheme, k = raw.get("robust"), raw.get("scheme"), raw.get("k")
        if name not in _KERNELS or scheme not in (0, 1) or not (is_number(k) and k > 0):
            raise BadData(
                f"{where}: robust kernel must be one of {_KERNELS} with scheme 0/1 and "
                f"k > 0, got {name!r}, {scheme!r}, {k!r}"
            )
        base = decode_noise(raw.get("base"), where, 1)
        return nm.Robust.Create(_make_kernel(name, scheme, float(k)), base)
    if "unit" in raw:
        return nm.Unit.Create(_dim(raw["unit"], where))
    if "isotropic" in raw:
        sigma = raw.get("sigma")
        if not (is_number(sigma) and sigma > 0):
            raise BadData(f"{where}: isotropic sigma must be > 0, got {sigma!r}")
        return nm.Isotropic.Sigma(_dim(raw["isotropic"], where), float(sigma))
    if "sigmas" in raw:
        sigmas = checked_numbers(raw["sigmas"], f"{where}: sigmas")
        if not (1 <= len(sigmas) <= 64 and min(sigmas) > 0):
            raise BadData(f"{where}: need 1 to 64 sigmas > 0, got {sigmas}")
        return nm.Diagonal.Sigmas(np.array(sigmas), False)
    if "sqrt_information" in raw:
        rows = raw["sqrt_information"]
        if not isinstance(rows, list) or not 1 <= len(rows) <= 64:
            raise BadData(f"{where}: sqrt_information must be a list of 1 to 64 rows")
        R = np.array([checked_numbers(r, f"{where}: sqrt_information") for r in rows], dtype=object)
        if R.ndim != 2 or R.shape[0] != R.shape[1]:
            raise BadData(f"{where}: sqrt_information must be square")
        R = R.astype(float)
        if np.abs(np.tril(R, -1)).max(initial=0.0) != 0 or not (np.diag(R) > 0).all():
            raise BadData(
                f"{where}: sqrt_information must be upper triangular with a positive diagonal"
            )
        return nm.Gaussian.SqrtInformation(R, False)
    raise BadData(f"{where}: unknown noise model {sorted(raw)}")


# the kinds of Values entries a session saves, tried in this order (getter: `at` + Kind)
VALUE_KINDS = ("pose3", "pose2", "rot3", "rot2", "vector")


def encode_values(values: gtsam.Values, where: str) -> list:
    out = []
    for key in values.keys():
        for kind in VALUE_KINDS:
            try:
                value = getattr(values, "at" + kind.capitalize())(key)
            except RuntimeError:
                continue
            numbers = encode_measurement(kind, value)
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


def decode_values(raw, where: str) -> gtsam.Values:
    if not isinstance(raw, list):
        raise BadData(f"{where}: values must be a list")
    values = gtsam.Values()
    for entry in raw:
        if not (
            isinstance(entry, list)
            and len(entry) == 3
            and is_key(entry[0])
            and entry[1] in VALUE_KINDS
        ):
            raise BadData(f"{where}: a value must be [key, kind, numbers], got {str(entry)[:80]}")
        key, kind, numbers = entry
        label = f"{where}, value {key_name(key)}"
        if values.exists(key):
            raise BadData(f"{label}: key given twice")
        values.insert(key, decode_measurement(kind, checked_numbers(numbers, label), label))
    return values


def is_key(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and 0 <= x < 2**64


def is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def checked_numbers(raw, where: str) -> list:
    if not isinstance(raw, list) or not all(is_number(x) for x in raw) or len(raw) > 4096:
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
