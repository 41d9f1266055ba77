"""Scenario `feng-probabilistic`: seed 000 (000_05137a0a9c449be3.txt) Sec. VI-B, a climbing
robot's camera on ceiling I or II seeing three ground robots, P3P candidates per update, noisy
odometry; and the camera, projection and odometry-noise models the seed's simulators share
(docs/design_datasets.md, "Seed 000")."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path

from typing import Literal
import gtsam
import numpy as np

from graphloc.cameras import PinholeCamera
from graphloc.config import parse_overrides
from graphloc.config_schema import config_dataclass, setting
from graphloc.datasets.camera_track import CameraTrackLog, write_camera_track
from graphloc.vision.marker_poses import p3p_candidate_sets

CEILINGS = ("level", "sloped")
# "loop": not in the seed, a closed circle for long runs
CURVES = ("line", "sine", "quadratic", "loop")
LOOP_RADIUS = 0.6
FIELD = 3.0  # side of the square field / ceiling [m] (Sec. VI-B)
GROUND_ROBOTS = ((0.5, 0.5, 0.3), (0.5, 2.5, 0.4), (2.5, 1.5, 0.2))  # Sec. VI-B
ODOMETRY_MODELS = ("per_axis", "isotropic")  # readings of "15% on all three dimensions"


def seed000_camera() -> PinholeCamera:
    """Camera C of the climbing robot: 640x480, horizontal FOV 2/3 pi (Sec. VI-A)."""
    return PinholeCamera.from_fov(640, 480, 2.0 * np.pi / 3.0)


def project_world(camera: PinholeCamera, R_wc: np.ndarray, t_wc: np.ndarray, points: np.ndarray):
    """Pixels (T,P,2) of world points (P,3) seen from cameras R_wc (T,3,3), t_wc (T,3), and the
    (T,P) visibility mask, in one batched camera.project call."""
    pc = np.einsum("tji,tpj->tpi", R_wc, points[None, :, :] - t_wc[:, None, :])
    uv, visible = camera.project(pc.reshape(-1, 3))
    return uv.reshape(pc.shape[:2] + (2,)), visible.reshape(pc.shape[:2])


MAX_FRAMES = 100_000  # frames of one simulated run


@dataclass(frozen=True)
class Plane:
    """A surface the climbing robot moves on: origin (3,), in-plane unit axes u, v (3,), inward
    unit normal (3,) (pointing into the room), half extents along u and v [m]."""

    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    normal: np.ndarray
    half_u: float
    half_v: float


def ceiling_plane(kind: str) -> Plane:
    """Ceiling I (level, 3 m) or ceiling II (45 deg, from 2 m at x=0 to 5 m at x=3), Sec. VI-B."""
    if kind == "level":
        return Plane(
            np.array([1.5, 1.5, 3.0]),
            np.array([1.0, 0, 0]),
            np.array([0, 1.0, 0]),
            np.array([0, 0, -1.0]),
            FIELD / 2,
            FIELD / 2,
        )
    if kind == "sloped":
        s = 1.0 / np.sqrt(2.0)
        return Plane(
            np.array([1.5, 1.5, 3.5]),
            np.array([s, 0, s]),
            np.array([0, 1.0, 0]),
            np.array([s, 0, -s]),
            FIELD / 2 / s,
            FIELD / 2,
        )
    raise ValueError(f"unknown ceiling {kind!r}; expected one of {CEILINGS}")


def curve_points(
    kind: str, arc_lengths: np.ndarray, half_u: float, half_v: float
) -> tuple[np.ndarray, np.ndarray]:
    """In-plane (u, v) points (N,2) at the given arc lengths along curve `kind` from the origin
    (x increasing), and the (N,) mask of points still inside the ceiling boundary. "loop" is
    a circle of radius LOOP_RADIUS through the origin that never reaches the boundary."""
    if kind == "loop":
        phi = arc_lengths / LOOP_RADIUS
        uv = LOOP_RADIUS * np.stack([np.sin(phi), 1.0 - np.cos(phi)], axis=1)
        return uv, np.ones(len(arc_lengths), dtype=bool)
    x = np.linspace(0.0, half_u, 20001)
    if kind == "line":
        y = 0.5 * x
    elif kind == "sine":
        y = np.sin(2.0 * x)
    elif kind == "quadratic":
        y = x**2
    else:
        raise ValueError(f"unknown curve {kind!r}; expected one of {CURVES}")
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    inside_curve = np.abs(y) <= half_v
    s_end = s[np.argmin(inside_curve)] if not inside_curve.all() else s[-1]
    xs = np.interp(arc_lengths, s, x)
    ys = np.interp(arc_lengths, s, y)
    return np.stack([xs, ys], axis=1), arc_lengths < s_end


def look_at(positions: np.ndarray, target: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Rotations R_wc (N,3,3): optical axis z_c at `target`, image x along `heading` (N,3)."""
    z = target - positions
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x = heading - np.sum(heading * z, axis=1, keepdims=True) * z
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=2)


def noisy_pixels(uv: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Pixel noise N(0, sigma) along a uniformly random direction (Sec. VI-A)."""
    r = rng.normal(0.0, sigma, uv.shape[:-1])
    phi = rng.uniform(0.0, 2.0 * np.pi, uv.shape[:-1])
    return uv + np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def relative_poses(R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Relative poses T_{k}^-1 T_{k+1}: rotations (N-1,3,3), translations (N-1,3) in frame k."""
    Rrel = np.einsum("kji,kjl->kil", R[:-1], R[1:])
    trel = np.einsum("kji,kj->ki", R[:-1], t[1:] - t[:-1])
    return Rrel, trel


# ---- Sec. VI-B: probabilistic setup ----------------------------------------------------------
@config_dataclass
class FengProbabilisticConfig:
    """Sec. VI-B. odometry_noise: relative sigma on each of the three translation components of
    a_t (0.15 = 15 %); odometry_rot_sigma: gyro noise per update [rad] (not given in the seed);
    odometry_model: how the 15 % apply (ODOMETRY_MODELS, `noisy_odometry`); max_time: cap on
    the run length [s] (None = until the ceiling boundary)."""

    ceiling: Literal[CEILINGS] = "level"
    curve: Literal[CURVES] = "line"
    speed: float = setting(0.2, ge=1e-3, le=10.0)
    rate_hz: float = setting(10.0, gt=0.0, le=1000.0)
    first_interval: float = setting(0.3, gt=0.0)
    odometry_noise: float = setting(0.15, ge=0.0)
    odometry_rot_sigma: float = setting(0.002, ge=0.0)
    odometry_model: Literal[ODOMETRY_MODELS] = "per_axis"
    pixel_sigma: float = setting(0.5, ge=0.0)
    max_time: float | None = setting(None, gt=0.0, le=1e5)
    seed: int = 0


@dataclass(frozen=True)
class FengRun:
    """One simulated run. times (T,); true camera poses R_wc (T,3,3), t_wc (T,3); landmarks (3,3);
    pixels (T,3,2) noisy; odometry: T-1 noisy relative camera poses (frame of the earlier pose);
    candidates: T CandidateSets; plane: the surface."""

    times: np.ndarray
    R_wc: np.ndarray
    t_wc: np.ndarray
    landmarks: np.ndarray
    pixels: np.ndarray
    odometry: list
    candidates: list
    plane: Plane

    def __len__(self) -> int:
        return len(self.times)


def noisy_odometry(
    Rrel: np.ndarray,
    trel: np.ndarray,
    rel_sigma: float,
    rot_sigma: float,
    rng: np.random.Generator,
    model: str = "per_axis",
) -> list[gtsam.Pose3]:
    """Odometry a_t (Sec. VI-B: "a Gaussian noise of a standard deviation 15% on all three
    dimensions"), two readings: "per_axis" scales each translation component by
    (1 + N(0, rel_sigma)); "isotropic" adds N(0, (rel_sigma |a|)^2 I) (15 % of the step length
    on every axis). Rotation perturbed by Exp(N(0, rot_sigma^2 I))."""
    noise = rng.standard_normal(trel.shape)
    if model == "per_axis":
        tn = trel * (1.0 + rel_sigma * noise)
    elif model == "isotropic":
        tn = trel + rel_sigma * np.linalg.norm(trel, axis=-1, keepdims=True) * noise
    else:
        raise ValueError(f"noisy_odometry: model must be one of {ODOMETRY_MODELS}, got {model!r}")
    w = rot_sigma * rng.standard_normal(trel.shape)
    return [
        gtsam.Pose3(gtsam.Rot3(R).compose(gtsam.Rot3.Expmap(wk)), tk)
        for R, tk, wk in zip(Rrel, tn, w)
    ]


def odometry_covariance(
    relative: gtsam.Pose3,
    rel_sigma: float = 0.15,
    rot_sigma: float = 0.002,
    floor: float = 1e-3,
    model: str = "per_axis",
) -> np.ndarray:
    """6x6 covariance (GTSAM tangent order) matching `noisy_odometry`: rotation rot_sigma (floor
    1e-6), translation component i sigma = rel_sigma |a_i| + floor ("per_axis") or
    rel_sigma |a| + floor on every axis ("isotropic"), from the measured a."""
    a = np.abs(relative.translation())
    if model == "isotropic":
        a = np.full(3, np.linalg.norm(a))
    elif model != "per_axis":
        raise ValueError(
            f"odometry_covariance: model must be one of {ODOMETRY_MODELS}, got {model!r}"
        )
    return np.diag(
        np.concatenate([np.full(3, max(rot_sigma, 1e-6) ** 2), (rel_sigma * a + floor) ** 2])
    )


class FengProbabilisticScenario:
    """Sec. VI-B: `simulate(config) -> FengRun` in memory; `generate` writes one run as a log
    (`graphloc simulate feng-probabilistic`)."""

    name = "feng-probabilistic"
    config_class = FengProbabilisticConfig

    @classmethod
    def generate(cls, out_dir, seed: int = 0, **overrides) -> Path:
        config = replace(
            FengProbabilisticConfig(seed=seed),
            **parse_overrides(FengProbabilisticConfig, overrides),
        )
        run = cls.simulate(config)
        cov = [
            odometry_covariance(
                o, config.odometry_noise, config.odometry_rot_sigma, model=config.odometry_model
            )
            for o in run.odometry
        ]
        log = CameraTrackLog(
            name=cls.name,
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

    @staticmethod
    def trajectory(
        config: FengProbabilisticConfig,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Plane]:
        """Update times (first interval 0.3 s, then 1/rate) up to the ceiling boundary, true
        camera rotations (T,3,3) and positions (T,3), and the ceiling plane."""
        plane = ceiling_plane(config.ceiling)
        if config.curve == "loop" and config.max_time is None:
            raise ValueError(
                "the 'loop' curve never reaches the boundary: set FengProbabilisticConfig.max_time"
            )
        length = 2.0 * (plane.half_u + plane.half_v) * 3.0
        t_max = length / config.speed if config.max_time is None else config.max_time
        if t_max * config.rate_hz > MAX_FRAMES:
            raise ValueError(
                f"FengProbabilisticConfig: {t_max:.4g} s at rate_hz {config.rate_hz:g} is "
                f"{t_max * config.rate_hz:.4g} frames, more than {MAX_FRAMES}: raise speed or "
                f"lower rate_hz / max_time"
            )
        times = np.concatenate(
            [[0.0], config.first_interval + np.arange(0.0, t_max, 1.0 / config.rate_hz)]
        )
        uv, inside = curve_points(config.curve, config.speed * times, plane.half_u, plane.half_v)
        times, uv = times[inside], uv[inside]
        if len(times) < 3:
            raise ValueError(
                f"trajectory of {config.curve} on {config.ceiling} ceiling has < 3 updates"
            )
        pos = plane.origin + uv[:, :1] * plane.u + uv[:, 1:] * plane.v
        # heading: curve tangent (finite differences on a fine step)
        uv_ahead, _ = curve_points(
            config.curve, config.speed * times + 1e-3, plane.half_u, plane.half_v
        )
        d = uv_ahead - uv
        heading = d[:, :1] * plane.u + d[:, 1:] * plane.v
        centroid = np.mean(np.asarray(GROUND_ROBOTS), axis=0)
        return times, look_at(pos, centroid, heading), pos, plane

    @classmethod
    def simulate(cls, config: FengProbabilisticConfig = FengProbabilisticConfig()) -> FengRun:
        rng = np.random.default_rng(config.seed)
        times, R, t, plane = cls.trajectory(config)
        landmarks = np.asarray(GROUND_ROBOTS, dtype=float)
        camera = seed000_camera()
        uv, inside = project_world(camera, R, t, landmarks)
        if not inside.all():
            k = int(np.argmin(inside.all(axis=1)))
            raise ValueError(f"ground robots leave the image at update {k} (t={times[k]:.2f} s)")
        pixels = noisy_pixels(uv, config.pixel_sigma, rng)
        Rrel, trel = relative_poses(R, t)
        odometry = noisy_odometry(
            Rrel,
            trel,
            config.odometry_noise,
            config.odometry_rot_sigma,
            rng,
            config.odometry_model,
        )
        candidates = p3p_candidate_sets(
            camera,
            list(pixels),
            [np.arange(3)] * len(times),
            landmarks,
            times,
            config.pixel_sigma,
            truth_t=t,
            observer="ground",
            observed="climber",
        )
        return FengRun(times, R, t, landmarks, pixels, odometry, candidates, plane)
