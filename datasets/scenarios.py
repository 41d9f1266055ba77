"""The simulator protocol behind `graphloc simulate NAME --out DIR [--seed N] [--FIELD VALUE]`.

A scenario is a class registered in `graphloc.datasets` (`_REGISTRY`) that implements
`Scenario`: class attributes `name` (its registered name) and `config_class` (a frozen
dataclass of its settings) and a classmethod `generate(out_dir, seed=0, **overrides) -> Path`
that writes one run as a log directory the loaders read (`graphloc.datasets.open_run`, log
format version 2, docs/log_format.md) with ground truth, and returns the manifest's path.
`overrides` are fields of `config_class`, as values or strings (`graphloc.config.parse_overrides`).
`generate(name, out_dir, seed, overrides)` is the one entry point (the `simulate` verb,
`graphloc.experiments.team_runs`).

The camera-track scenarios write through `graphloc.datasets.camera_track`; seed 000 Sec. VI-A's
trial (`feng-deterministic`) has its class here, beside the protocol, because its simulation
module (`feng_deterministic`) is shared with the straight-line baseline's experiments.
"""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import asdict, replace
from pathlib import Path
from typing import ClassVar, Protocol

import gtsam
import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.config import parse_overrides
from graphloc.datasets import _REGISTRY, dataset_class
from graphloc.datasets.camera_track import CameraTrackLog, write_camera_track
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
STRAIGHT_ROT_SIGMA = 0.01  # [rad] heading change allowed by "moves straight" (seed 000 Sec. IV)


class FengDeterministicScenario:
    """Seed 000 Sec. VI-A, one trial: three tilted omni ground cameras (mutual pixels in
    meta["mutual_pixels"], 512x512, N(0, 0.5) px) and the climbing camera's three snapshots
    of them along its straight two-step move. The ground robots' true positions are the static
    target's marker layout in the manifest (ground truth: a localizer must estimate C2, C3 from
    the mutual pixels, e.g. with graphloc.vision.mutual -- meta["mutual_estimate"] is that
    estimate); the climber's `markers` table holds its pixels of them, its `relative_pose3`
    table the straight-move assumption as odometry."""

    name = "feng-deterministic"

    config_class = TableIConfig

    @classmethod
    def generate(cls, out_dir, seed: int = 0, **overrides) -> Path:
        config = replace(
            TableIConfig(trials=1, seed=seed, workers=1), **parse_overrides(TableIConfig, overrides)
        )
        trials = simulate_straight_line_trials(
            1, seed=seed, config=Seed000Config(pixel_sigma=config.pixel_sigma)
        )
        tri = ground_triangle(trials.ground, config, np.random.default_rng([seed, 1]))
        K = trials.K
        camera = PinholeCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], 640, 480)
        times = np.arange(3, dtype=float)
        # the seed's motion assumption as odometry: the climber moves straight without turning
        # (rotation known to STRAIGHT_ROT_SIGMA), by an unknown step (translation sigma = 3 x the
        # mean step); the straight-line baseline uses the collinearity of the same motion instead
        steps = [gtsam.Pose3()] * 2
        cov = [
            np.diag([STRAIGHT_ROT_SIGMA**2] * 3 + [(3 * Seed000Config().step_mean) ** 2] * 3)
        ] * 2
        log = CameraTrackLog(
            name=cls.name,
            times=times,
            R_wc=np.repeat(trials.R_wc, 3, axis=0),
            t_wc=trials.positions[0],
            layout=trials.ground[0],
            pixels=trials.pixels[0],
            camera=camera,
            pixel_sigma=config.pixel_sigma,
            odometry=steps,
            odometry_cov=cov,
            meta={
                "seed_paper": "000_05137a0a9c449be3.txt Sec. VI-A",
                "config": asdict(config),
                "ground_R_wc": tri.R[0].tolist(),
                "mutual_pixels": tri.pixels[0].tolist(),
                "mutual_estimate": tri.estimated[0].tolist(),
                "mutual_status": str(tri.status[0]),
                "omni": {"size": config.omni_size, "max_polar_angle": config.omni_max_polar},
            },
        )
        return write_camera_track(log, out_dir)
