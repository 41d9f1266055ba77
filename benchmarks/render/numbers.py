"""The number formats the renderers share: one place for "n/a", "inf", "yes" / "no" and
significant digits."""

from __future__ import annotations

import pandas as pd


def fmt(x, spec: str = ".2e", missing: str = "n/a") -> str:
    """x formatted with `spec`, or `missing` for None."""
    return missing if x is None else format(x, spec)


def dev(x) -> str:
    """A deviation |ours / paper - 1|; "inf" for a reading that produced no number."""
    return "inf" if x is None or not x < float("inf") else f"{x:.2f}"


def joined(values, spec: str = ".2f") -> str:
    """Values as "a / b / c"."""
    return " / ".join(format(v, spec) for v in values)


def yes_no(flag) -> str:
    return "yes" if flag else "no"


def significant(frame: pd.DataFrame, digits: int) -> pd.DataFrame:
    """A frame's floats to `digits` significant digits (nan where a row has no such number),
    its other cells as they are."""
    return frame.map(lambda x: format(x, f".{digits}g") if isinstance(x, float) else x)
