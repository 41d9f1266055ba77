"""SO(3) helpers shared by the batched numpy code paths."""

from __future__ import annotations

import numpy as np


def skew(v) -> np.ndarray:
    """Batched hat operator: (...,3) vectors -> (...,3,3) matrices [v]x with [v]x w = v x w."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape + (3,))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out
