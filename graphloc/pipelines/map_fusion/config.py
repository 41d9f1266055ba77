"""`fuse-maps --config FILE`: the fusion settings as TOML (read with tomllib).

Tables and keys are the fields of the dataclasses they fill; anything not given keeps its
default. Lists become tuples. Unknown tables or keys are a ValueError naming the file.

    [registration]          # graphloc.mapping.registration.RegistrationConfig
    voxel = 0.03
    normal_radius = 0.25
    [acceptance]            # graphloc.mapping.acceptance.AcceptanceConfig
    min_inlier_ratio = 0.65
    ceiling_above = true
    [fusion]                # scalar fields of graphloc.pipelines.map_fusion.types.FusionConfig
    guess_sigma = [0.0873, 0.1]   # 1-sigma of the inter-robot guess: rot [rad], trans [m]
    robust = true
    [odometry]              # graphloc.mapping.odometry.OdometryConfig
    voxel_size = 0.08
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

from graphloc.mapping.acceptance import AcceptanceConfig
from graphloc.pipelines.map_fusion.types import FusionConfig
from graphloc.mapping.odometry import OdometryConfig
from graphloc.mapping.registration import RegistrationConfig

_NESTED = {
    "registration": RegistrationConfig,
    "acceptance": AcceptanceConfig,
    "odometry": OdometryConfig,
}


def _build(cls, values: dict, path: Path, table: str):
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - names)
    if unknown:
        raise ValueError(
            f"{path}: [{table}] has unknown key(s) {', '.join(unknown)} "
            f"(known: {', '.join(sorted(names))})"
        )
    kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    try:
        return cls(**kwargs) if cls is not FusionConfig else kwargs
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: [{table}]: {exc}") from None


def load_fusion_config(path) -> FusionConfig:
    """FusionConfig from a TOML file (module docstring); ValueError naming the file on bad input."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML ({exc})") from None
    unknown = sorted(set(data) - set(_NESTED) - {"fusion"})
    if unknown:
        raise ValueError(
            f"{path}: unknown table(s) {', '.join(unknown)} (known: fusion, {', '.join(_NESTED)})"
        )
    for table, values in data.items():
        if not isinstance(values, dict):
            raise ValueError(f"{path}: {table} must be a table ([{table}])")
    nested = {k: _build(cls, data[k], path, k) for k, cls in _NESTED.items() if k in data}
    scalars = _build(FusionConfig, data.get("fusion", {}), path, "fusion")
    bad = sorted(set(scalars) & (set(_NESTED) | {"tracker", "session"}))
    if bad:
        raise ValueError(f"{path}: [fusion] cannot set {', '.join(bad)}; use its own table")
    try:
        return FusionConfig(**nested, **scalars)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: [fusion]: {exc}") from None
