"""The simulator protocol behind `graphloc simulate NAME --out DIR [--seed N] [--FIELD VALUE]`:
a registered class with `name`, `config_class` and `generate(out_dir, seed, **overrides)` that
writes a log directory with ground truth; and seed 000 Sec. VI-A's `feng-deterministic`."""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path
from typing import ClassVar, Protocol

import numpy as np

from graphloc.config import parse_overrides
from graphloc.datasets import scenario_class
from graphloc.datasets.formation_log import write_table_i_trial
from graphloc.datasets.feng_deterministic import (
    Seed000Config,
    TableIConfig,
    ground_triangle,
    simulate_straight_line_trials,
)


class Scenario(Protocol):
    """What `graphloc simulate` needs from a scenario class registered in
    `graphloc.datasets.SCENARIOS`: `config_class` a dataclass whose fields are the overrides."""

    name: ClassVar[str]
    config_class: ClassVar[type]

    @classmethod
    def generate(cls, out_dir, seed: int = 0, **overrides) -> Path: ...


def scenario_config_class(name: str) -> type:
    """The config dataclass of scenario `name` (its fields are `generate`'s overrides)."""
    return scenario_class(name).config_class


def generate(name: str, out_dir, seed: int = 0, overrides: dict | None = None) -> Path:
    """Write one run of scenario `name` to out_dir; returns the manifest's path."""
    return scenario_class(name).generate(out_dir, seed, **dict(overrides or {}))


# ---- seed 000 Sec. VI-A ------------------------------------------------------------------------


class FengDeterministicScenario:
    """Seed 000 Sec. VI-A, one trial as measurements only (`formation_log`): C2, C3 are to be
    placed by mutual bearings and the climber by its views of the three."""

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
