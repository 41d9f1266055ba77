"""Scenario generators behind `graphloc simulate NAME --out DIR [--seed N] [--set KEY=VALUE]`.

A scenario is a registered class (graphloc.datasets._REGISTRY) with `name`, `config_class`
(a frozen dataclass) and `generate(out_dir, seed, **overrides) -> Path` writing one run in the
project's log format (docs/log_format.md, graphloc.io) plus 3D ground truth. 3D poses have no
table in log format version 1, so they go next to it as TUM files (timestamp tx ty tz qx qy
qz qw, what evo reads) named in manifest["meta"]: "groundtruth_tum" (true camera poses) and
"odometry_tum" (the noisy odometry integrated from the true first pose).

The seed 000 scenarios are adapters over the one implementation of each simulation:
`feng-deterministic` (Sec. VI-A, graphloc.datasets.feng_deterministic + ground omni cameras as in
graphloc.datasets.feng_deterministic.ground_triangle) and `feng-probabilistic` (Sec. VI-B,
graphloc.datasets.feng.FengProbabilisticScenario). `dual-robot-room` writes its own format
(graphloc.datasets.dual_room.DualRoomScenario.write).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Protocol

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.cameras import PinholeCamera
from graphloc.datasets import _REGISTRY, dataset_class
from graphloc.datasets.feng import (
    FengProbabilisticConfig,
    FengProbabilisticScenario,
    odometry_covariance,
    seed000_camera,
)
from graphloc.datasets.feng_deterministic import (
    Seed000Config,
    TableIConfig,
    ground_triangle,
    simulate_straight_line_trials,
)
from graphloc.eval import write_tum
from graphloc.io import write_manifest, write_table


class Scenario(Protocol):
    name: str
    config_class: type

    def generate(self, out_dir, seed: int = 0, **overrides) -> Path: ...


def parse_overrides(config_class: type, overrides: dict) -> dict:
    """KEY=VALUE strings (or values) -> typed fields of `config_class`; unknown keys and
    unparsable values raise ValueError naming the field."""
    known = {f.name: f for f in dataclasses.fields(config_class)}
    out = {}
    for key, value in overrides.items():
        if key not in known:
            raise ValueError(
                f"{config_class.__name__}: unknown field {key!r}; known: {', '.join(sorted(known))}"
            )
        default = getattr(config_class(), key)
        if isinstance(value, str) and not isinstance(default, str):
            try:
                value = json.loads(value)
            except json.JSONDecodeError:
                raise ValueError(f"{config_class.__name__}.{key}: cannot parse {value!r}") from None
        if isinstance(default, bool) != isinstance(value, bool) or (
            isinstance(default, (int, float)) and not isinstance(value, (int, float))
        ):
            raise ValueError(
                f"{config_class.__name__}.{key}: expected {type(default).__name__}, got {value!r}"
            )
        if isinstance(default, int) and not isinstance(default, bool) and value != int(value):
            raise ValueError(f"{config_class.__name__}.{key}: expected an integer, got {value!r}")
        out[key] = (
            type(default)(value)
            if isinstance(default, (int, float)) and not isinstance(default, bool)
            else value
        )
    return out


@dataclass(frozen=True)
class CameraTrackLog:
    """One camera (robot `observer`, body frame = camera frame) watching the markers of a static
    `target` (layout (m,3) in the target's frame, the target at the world origin).
    times (T,); true camera poses R_wc (T,3,3), t_wc (T,3); pixels (T,m,2) noisy (NaN = not
    seen); camera: PinholeCamera; odometry: T-1 noisy relative poses (gtsam.Pose3) with their
    diagonal 6x6 covariances odometry_cov, or []; surface: (point, normal) of the plane the
    camera moves on, or None; identical_markers: the markers cannot be told apart (seed 001);
    meta: free-form."""

    name: str
    times: np.ndarray
    R_wc: np.ndarray
    t_wc: np.ndarray
    layout: np.ndarray
    pixels: np.ndarray
    camera: object
    pixel_sigma: float
    odometry: list
    odometry_cov: list
    observer: str = "climber"
    target: str = "ground"
    surface: tuple | None = None
    identical_markers: bool = False
    meta: dict = dataclasses.field(default_factory=dict)


def write_camera_track(log: CameraTrackLog, out_dir) -> Path:
    """Write `log` as a graphloc log directory (format version 2: markers, relative_pose3,
    groundtruth TUM); returns the manifest path."""
    out = Path(out_dir)
    obs = log.observer
    markers = [
        (float(tk), "camera", log.target, j, float(u), float(v))
        for tk, px in zip(log.times, log.pixels)
        for j, (u, v) in enumerate(px)
        if np.isfinite([u, v]).all()
    ]
    write_table(out / obs / "markers.csv", "markers", markers)
    tables = {"markers": f"{obs}/markers.csv", "groundtruth": f"{obs}/groundtruth.tum"}
    poses = np.broadcast_to(np.eye(4), (len(log.times), 4, 4)).copy()
    poses[:, :3, :3], poses[:, :3, 3] = log.R_wc, log.t_wc
    write_tum(out / obs / "groundtruth.tum", log.times, poses)
    sensors = []
    if log.odometry:
        rows = []
        for t0, t1, step, cov in zip(log.times[:-1], log.times[1:], log.odometry, log.odometry_cov):
            qx, qy, qz, qw = Rotation.from_matrix(step.rotation().matrix()).as_quat()
            rows.append(
                (
                    float(t1),
                    "odometry",
                    float(t0),
                    *map(float, step.translation()),
                    qx,
                    qy,
                    qz,
                    qw,
                    *map(float, np.sqrt(np.diag(cov))),
                )
            )
        write_table(out / obs / "relative_pose3.csv", "relative_pose3", rows)
        tables["relative_pose3"] = f"{obs}/relative_pose3.csv"
        sensors.append({"name": "odometry", "type": "odometry"})
    cam = log.camera
    sensors.append(
        {
            "name": "camera",
            "type": "camera",
            "params": {**cam.params(), "pixel_sigma": log.pixel_sigma},
        }
    )
    climber = {
        "name": obs,
        "kind": "ceiling",
        "planar": False,
        "sensors": sensors,
        "tables": tables,
    }
    if log.surface is not None:
        climber["surface"] = {
            "point": [float(a) for a in log.surface[0]],
            "normal": [float(a) for a in log.surface[1]],
        }
    manifest = {
        "name": log.name,
        "robots": [
            climber,
            {
                "name": log.target,
                "kind": "ground",
                "static": True,
                "initial_pose": [0, 0, 0, 0, 0, 0, 1],
                "markers": np.asarray(log.layout, dtype=float).tolist(),
                "identical_markers": log.identical_markers,
                "sensors": [],
                "tables": {},
            },
        ],
        "meta": {"scenario": log.name, **log.meta},
    }
    return write_manifest(manifest, out)


# ---- seed 000 adapters -----------------------------------------------------------------------
STRAIGHT_ROT_SIGMA = 0.01  # [rad] heading change allowed by "moves straight" (seed 000 Sec. IV)


class FengDeterministicScenario:
    """Seed 000 Sec. VI-A, one trial: three tilted omni ground cameras (mutual pixels in
    meta["mutual_pixels"], 512x512, N(0, 0.5) px) and the climbing camera's three snapshots
    of them along its straight two-step move. landmarks.csv holds the true ground positions
    (ground truth; a localizer must estimate C2, C3 from the mutual pixels, e.g. with
    graphloc.vision.mutual -- meta["mutual_estimate"] is that estimate); the candidates table
    holds P3P on the true positions."""

    name = "feng-deterministic"

    config_class = TableIConfig

    def generate(self, out_dir, seed: int = 0, **overrides) -> Path:
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
            name=self.name,
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


class FengProbabilisticLog:
    """Seed 000 Sec. VI-B, one run (graphloc.datasets.feng.FengProbabilisticScenario.simulate)."""

    name = "feng-probabilistic"

    config_class = FengProbabilisticConfig

    def generate(self, out_dir, seed: int = 0, **overrides) -> Path:
        config = replace(
            FengProbabilisticConfig(seed=seed),
            **parse_overrides(FengProbabilisticConfig, overrides),
        )
        run = FengProbabilisticScenario.simulate(config)
        cov = [
            odometry_covariance(o, config.odometry_noise, config.odometry_rot_sigma)
            for o in run.odometry
        ]
        log = CameraTrackLog(
            name=self.name,
            times=run.times,
            R_wc=run.R_wc,
            t_wc=run.t_wc,
            layout=run.landmarks,
            pixels=run.pixels,
            camera=seed000_camera(),
            pixel_sigma=config.pixel_sigma,
            odometry=run.odometry,
            odometry_cov=cov,
            surface=(run.plane.origin, run.plane.normal),
            meta={"seed_paper": "000_05137a0a9c449be3.txt Sec. VI-B", "config": asdict(config)},
        )
        return write_camera_track(log, out_dir)


def _dual_robot_room(out_dir, seed: int, **overrides) -> Path:
    # imported here, not at the top: the room's ray-casting loads Open3D, which the seed 000 /
    # 004 / 001 scenarios (and `graphloc --help`) do not need
    from graphloc.datasets.dual_room import DualRoomConfig, DualRoomScenario, variant_config

    kw = parse_overrides(DualRoomConfig, overrides)
    kw.pop("seed", None)
    out = Path(out_dir)
    DualRoomScenario.simulate(variant_config(kw.pop("variant", "furnished"), seed, **kw)).write(out)
    return out


# registered names whose class is not itself a Scenario -> the generator that writes them
ADAPTERS = {
    "feng-probabilistic": lambda out, seed, **o: FengProbabilisticLog().generate(out, seed, **o),
    "dual-robot-room": _dual_robot_room,
}


def generate(name: str, out_dir, seed: int = 0, overrides: dict | None = None) -> Path:
    """Write one run of scenario `name` to out_dir (the `graphloc simulate` pipeline)."""
    cls = dataset_class(name)  # raises for unknown names
    overrides = dict(overrides or {})
    if name in ADAPTERS:
        return ADAPTERS[name](out_dir, seed, **overrides)
    if not (hasattr(cls, "generate") and hasattr(cls, "config_class")):
        raise ValueError(
            f"{name!r} has no log-format generator (not a `graphloc simulate` scenario); "
            f"scenarios: {', '.join(scenario_names())}"
        )
    return cls().generate(out_dir, seed, **overrides)


def scenario_names() -> list[str]:
    return sorted(
        n
        for n, (mod, cls) in _REGISTRY.items()
        if n in ADAPTERS or mod in ("scenarios", "kaushik", "breitenmoser")
    )
