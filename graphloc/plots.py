"""Generic result plots (matplotlib, Agg backend, PNG files): `plot_trajectories`, `plot_series`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from graphloc.names import written_whole  # noqa: E402


@dataclass(frozen=True)
class Series:
    """A labelled curve: x (N,) and y (N,) -- or for trajectories x = (N,2) positions and
    y = None."""

    label: str
    x: np.ndarray
    y: np.ndarray | None = None
    style: str = "-"
    color: str | None = None


def _xy(s: Series) -> tuple[np.ndarray, np.ndarray]:
    if s.y is None:
        a = np.asarray(s.x, dtype=float)
        if a.ndim != 2 or a.shape[1] < 2:
            raise ValueError(f"series {s.label!r}: positions must be (N,2+), got {a.shape}")
        return a[:, 0], a[:, 1]
    x, y = np.asarray(s.x, dtype=float), np.asarray(s.y, dtype=float)
    if x.shape != y.shape:
        raise ValueError(f"series {s.label!r}: x and y shapes differ {x.shape} vs {y.shape}")
    return x, y


def plot_trajectories(
    path: str | Path,
    series: list[Series],
    reference: list[Series] = (),
    points=None,
    title: str = "",
    point_label: str = "landmarks",
) -> Path:
    """Top view: estimated trajectories (solid), references (dashed black unless colored),
    optional points."""
    fig, ax = plt.subplots(figsize=(7, 7))
    for s in reference:
        x, y = _xy(s)
        ax.plot(
            x, y, s.style if s.style != "-" else "--", color=s.color or "k", lw=1.0, label=s.label
        )
    for s in series:
        x, y = _xy(s)
        ax.plot(x, y, s.style, lw=1.0, label=s.label, **_color(s))
    if points is not None and len(points):
        p = np.asarray(points, dtype=float)
        ax.plot(p[:, 0], p[:, 1], "k^", ms=6, label=point_label)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    ax.set_title(title)
    return _save(fig, path)


def plot_series(
    path: str | Path,
    series: list[Series],
    xlabel: str = "",
    ylabel: str = "",
    title: str = "",
    logy: bool = False,
) -> Path:
    """Curves y(x) on one axis (e.g. error over time, latency per frame)."""
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for s in series:
        x, y = _xy(s)
        ax.plot(x, y, s.style, lw=0.9, label=s.label, **_color(s))
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best", ncol=2)
    ax.set_title(title)
    return _save(fig, path)


def _color(s: Series) -> dict:
    return {} if s.color is None else {"color": s.color}


def _save(fig, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    try:
        with written_whole(path) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    return path
