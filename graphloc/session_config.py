"""The configuration of `graphloc.session.Session`: which solver (`MODES`), its GTSAM
parameters (Levenberg-Marquardt, iSAM2) and the fixed lag (`graphloc.fixed_lag`). Light: GTSAM
loads where a threshold map is built (the command line's options derive from `SessionConfig`)."""

from __future__ import annotations

from typing import Literal

from graphloc.config_schema import config_dataclass, setting

MODES = ("batch", "online")


@config_dataclass
class SessionConfig:
    """The solver of a `Session` and its parameters: "batch" (Levenberg-Marquardt, the `lm_*`
    fields) or "online" (iSAM2: relinearization, factorization, wildfire, step), `lag` /
    `marginalize_every` [s] for a fixed-lag window (`graphloc.fixed_lag`); each field in
    docs/design_core.md, "Session options"."""

    mode: Literal[MODES] = "batch"
    lm_max_iterations: int = setting(100, ge=1, le=100_000)
    lm_relative_error_tol: float = 1e-6
    lm_absolute_error_tol: float = 1e-6
    relinearize_threshold: float = setting(0.05, ge=0.0)
    relinearize_translation: float = setting(0.0, ge=0.0)
    relinearize_skip: int = setting(1, ge=1, le=100_000)
    extra_updates: int = setting(0, ge=0, le=1000)
    factorization: Literal["CHOLESKY", "QR"] = "CHOLESKY"
    wildfire_threshold: float = setting(0.001, ge=0.0)
    partial_relinearization_check: bool = False
    isam2_optimizer: Literal["gauss_newton", "dogleg"] = "gauss_newton"
    lag: float = setting(0.0, ge=0.0)
    marginalize_every: float = setting(0.0, ge=0.0)


THRESHOLD_SYMBOLS = {"x": 6, "s": 6, "l": 3, "k": 3, "q": 3}  # symbol -> dim (Pose3 / Point3)


def relinearize_threshold(config: SessionConfig):
    """What `ISAM2Params.setRelinearizeThreshold` takes: one number, or with
    `relinearize_translation` > 0 a map symbol -> thresholds per tangent component (Pose3:
    rotation then translation)."""
    trans = config.relinearize_translation
    if trans <= 0:
        return config.relinearize_threshold
    import gtsam
    import numpy as np

    out = gtsam.ISAM2ThresholdMap()
    for symbol, dim in THRESHOLD_SYMBOLS.items():
        rot = [config.relinearize_threshold] * 3 if dim == 6 else []
        out.insert((symbol, np.array(rot + [trans] * 3)))
    return out


def check_thresholded(config: SessionConfig, keys) -> None:
    """ValueError naming the keys the threshold map (`relinearize_translation` > 0) does not
    cover (iSAM2 would look up a symbol it does not hold)."""
    if config.relinearize_translation <= 0:
        return
    from graphloc.keys import decode
    from graphloc.keys import key_name

    bad = [key_name(k) for k in keys if decode(k)[0] not in THRESHOLD_SYMBOLS]
    if bad:
        raise ValueError(
            f"Session.add: keys {bad[:5]} have no relinearize threshold (relinearize_translation "
            f"> 0 covers the symbols {sorted(THRESHOLD_SYMBOLS)} only)"
        )
