"""The simulator protocol behind `graphloc simulate NAME --out DIR [--seed N] [--FIELD VALUE]`:
a registered class with `name`, `config_class` and `generate(out_dir, seed, **overrides)` that
writes a log directory with ground truth; and seed 000 Sec. VI-A's `feng-deterministic`."""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import asdict, replace
from pathlib import Path
from typing import ClassVar, Protocol

import numpy as np

from graphloc.config import parse_overrides
from graphloc.datasets import _REGISTRY, dataset_class
from graphloc.datasets.formation_log import write_table_i_trial
from graphloc.datasets.feng_deterministic import (
    Seed000Config,
    TableIConfig,
    ground_triangle,
    simulate_straight_line_trials,
)


class Scenario(Protocol):
    """What `graphloc simulate` needs from a registered scenario class."""

    name: ClassVar[str]
    config_class: ClassVar[type]

    @classmethod
    def generate(cls, out_dir, seed: int = 0, **overrides) -> Path: ...


def is_scenario(cls) -> bool:
    """`cls` implements `Scenario`: a classmethod `generate(out_dir, seed, **overrides)` and a
    dataclass `config_class`."""
    gen = inspect.getattr_static(cls, "generate", None)
    if not isinstance(gen, classmethod):
        return False
    params = list(inspect.signature(cls.generate).parameters.values())
    return (
        dataclasses.is_dataclass(getattr(cls, "config_class", None))
        and isinstance(getattr(cls, "name", None), str)
        and [p.name for p in params[:2]] == ["out_dir", "seed"]
        and params[-1].kind is inspect.Parameter.VAR_KEYWORD
    )


def scenario_class(name: str) -> type:
    """The registered class of scenario `name`; ValueError for unknown names and for
    registered classes that are not scenarios (loaders such as `mrclam`)."""
    cls = dataset_class(name)  # raises for unknown names
    if not is_scenario(cls):
        raise ValueError(
            f"{name!r} is not a scenario (no `generate` into a log directory); "
            f"scenarios: {', '.join(scenario_names())}"
        )
    return cls


def scenario_config_class(name: str) -> type:
    """The config dataclass of scenario `name` (its fields are `generate`'s overrides)."""
    return scenario_class(name).config_class


def generate(name: str, out_dir, seed: int = 0, overrides: dict | None = None) -> Path:
    """Write one run of scenario `name` to out_dir; returns the manifest's path."""
    return scenario_class(name).generate(out_dir, seed, **dict(overrides or {}))


def scenario_names() -> list[str]:
    """Registered names whose class implements `Scenario`."""
    return sorted(n for n in _REGISTRY if is_scenario(dataset_class(n)))


# ---- seed 000 Sec. VI-A ------------------------------------------------------------------------


class FengDeterministicScenario:
    """Seed 000 Sec. VI-A, one trial, as measurements only (`formation_log`): three tilted omni
    ground cameras that see each other (512x512, N(0, 0.5) px), C1 the reference with |T_12|
    known, and the climbing camera's three snapshots of them along its straight two-step move.
    A localizer must estimate C2, C3 from the mutual bearings and the climber from its views
    of the three (`graphloc smooth` does both in one graph)."""

    name = "feng-deterministic"

    config_class = TableIConfig

    @classmethod
    def generate(cls, out_dir, seed: int = 0, **overrides) -> Path:
        config = replace(
            TableIConfig(trials=1, seed=seed, workers=1), **parse_overrides(TableIConfig, overrides)
        )
        sim = Seed000Config(
            pixel_sigma=config.pixel_sigma,
            lateral_sigma=config.lateral_sigma,
            orientation=config.orientation,
        )
        trials = simulate_straight_line_trials(1, seed=seed, config=sim)
        tri = ground_triangle(trials.ground, config, np.random.default_rng([seed, 1]))
        meta = {
            "seed_paper": "000_05137a0a9c449be3.txt Sec. VI-A",
            "config": asdict(config),
            "omni": {"size": config.omni_size, "max_polar_angle": config.omni_max_polar},
        }
        step_sigma = 3 * sim.step_mean
        return write_table_i_trial(
            trials, tri, 0, config.pixel_sigma, step_sigma, cls.name, out_dir, meta
        )
