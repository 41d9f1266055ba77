"""The configuration of `graphloc.session.Session`: which solver (`MODES`), its GTSAM
parameters (Levenberg-Marquardt, iSAM2) and the fixed lag (`graphloc.fixed_lag`), and the checked
reading of a saved config (`config_from_dict`). Light: GTSAM loads where a threshold map is built
(the command line's options derive from `SessionConfig`)."""

from __future__ import annotations

from typing import Literal

from graphloc.config_schema import config_dataclass, setting
from graphloc.datafile import BadData

MODES = ("batch", "online")


@config_dataclass
class SessionConfig:
    """mode: "batch" (Levenberg-Marquardt) or "online" (iSAM2).

    LM: lm_max_iterations, lm_relative_error_tol, lm_absolute_error_tol.
    iSAM2: relinearize_threshold (on the delta of any variable), relinearize_translation (> 0:
    this threshold [m] on the translation of Pose3 variables and on Point3 variables,
    relinearize_threshold on the rotation only -- iSAM2's per-symbol threshold map, so every
    key must then be a Pose3 'x' / 's' or a Point3 'l' / 'k' / 'q', `THRESHOLD_SYMBOLS`),
    relinearize_skip (relinearize every N updates), extra_updates (additional `update()` calls
    after each add, to converge further), factorization ("CHOLESKY" or "QR"),
    wildfire_threshold (back-substitution stops where the solution changes less than this),
    partial_relinearization_check (only check the variables of re-eliminated cliques for
    relinearization), isam2_optimizer: "gauss_newton"
    (iSAM2's default step) or "dogleg" (Powell's dog leg with an adaptive trust region: a
    step that would raise the error is shortened, which stops the period-2 oscillation an
    undamped step can fall into on stiff graphs).
    lag [s]: online only; 0 keeps every variable (full smoothing); > 0 is a fixed lag: iSAM2
    that marginalizes, with `ISAM2::marginalizeLeaves`, every variable added more than `lag`
    seconds (of the add times) before the newest (`graphloc.fixed_lag`: a constrained ordering
    by add time keeps those variables leaves of the Bayes tree, so no re-elimination is
    needed; iSAM2 reuses the factor slots marginalization empties, `findUnusedFactorSlots`,
    else its factor list and a long run's per-step cost grow): the tree and the per-step cost
    stay bounded; a marginalized variable keeps its
    last estimate, and a factor on one is refused (`Session.add` raises ValueError;
    `Session.marginalized` tells first). A variable's stamp is its add time and is not renewed
    when later factors touch it, so long-lived variables (a static robot's pose, a SLAM
    landmark) leave the window too. marginalize_every [s] (0: `lag`): stamps are add times
    rounded down to a multiple of it; old variables leave in one batch every
    `marginalize_every` seconds (the window spans `lag` to `lag + marginalize_every`), and
    every update orders one group per live stamp.
    keep_steps: keep every `add` step (its factors and initial values) so that `Session.save`
    can write the session; False: the session keeps only what its solver needs (online: iSAM2's
    window and the marginalized variables' last estimates; batch: the graph and initial guess),
    so a long fixed-lag run grows only by those estimates, and `save` raises ValueError.
    """

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
    keep_steps: bool = True


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
    from graphloc.value_codec import key_name

    bad = [key_name(k) for k in keys if decode(k)[0] not in THRESHOLD_SYMBOLS]
    if bad:
        raise ValueError(
            f"Session.add: keys {bad[:5]} have no relinearize threshold (relinearize_translation "
            f"> 0 covers the symbols {sorted(THRESHOLD_SYMBOLS)} only)"
        )


def config_from_dict(raw) -> SessionConfig:
    """SessionConfig from its saved dict: every field known and of its type (strict, as any
    config dataclass: `graphloc.config`)."""
    if not isinstance(raw, dict):
        raise BadData("'config' must be an object")
    try:
        return SessionConfig(**raw)
    except ValueError as exc:
        raise BadData(f"config: {exc}") from None
