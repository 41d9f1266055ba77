"""Camera pixels as projection factors: marker pixels of a static or moving target (seed 000
Sec. III-B, seed 004 Sec. II-C) and feature tracks on one landmark per track with the seed's
weak depth prior (seed 003 II-B, eq. 14; docs/design_team_graph.md, "Feature tracks")."""

from __future__ import annotations


import gtsam
import numpy as np

from graphloc.factors.robust import robust_noise
from graphloc.geometry.so3 import skew
from graphloc.keys import frame_marker_key, landmark_key, marker_key, pose_key
from graphloc.pipelines.team_graph.config import FEATURE_BASE, GraphConfig, cov6
from graphloc.pipelines.team_graph.graph import SectionFactors
from graphloc.run import TeamRun


class FeatureTracks:
    """Feature pixels fed one at a time (`add`), causally: a track's landmark, its guess and
    its point prior come from the track's first pixel alone: `made` (factors, skips), each
    track's landmark guess ('from' its first pose, on the first ray at the depth prior) and the
    point priors ((key, sigma, time) each, placed at the guess once that pose has a value)."""

    def __init__(self, run: TeamRun, config: GraphConfig):
        self.run, self.config = run, config
        self.kernel = config.kernels.kernel("projection")
        self.tracks: dict = {}  # (robot, track) -> landmark key
        self.calibrations: dict = {}
        self.made = SectionFactors()
        self.landmark_guess: dict = {}
        self.point_priors: list = []

    def add(self, f, k: int, time: float) -> list:
        """Pixel `f` at its robot's pose k (-1: none within the sync tolerance; a counted skip
        `no_pose_at_time`) at that pose's `time`: its projection factor ((time, factor,
        "projection"), returned too: [] when skipped), a new track's landmark guess and point
        prior. A pixel that does not undistort is a counted skip `bad_pixel`."""
        run, skips = self.run, self.made.skips
        if k < 0:
            skips.add(
                "no_pose_at_time",
                f"robot {run.robots[f.robot].name}: feature track {f.track} at {f.time} has no "
                f"pose within the sync tolerance",
            )
            return []
        cam = f.camera
        if id(cam) not in self.calibrations:
            self.calibrations[id(cam)] = gtsam.Cal3_S2(cam.fx, cam.fy, 0.0, cam.cx, cam.cy)
        ideal = _ideal_pixel(cam, f.pixel)
        if ideal is None:
            skips.add(
                "bad_pixel",
                f"robot {run.robots[f.robot].name}: feature track {f.track} at {f.time}: pixel "
                f"{f.pixel.tolist()} does not undistort",
            )
            return []
        stream = (f.robot, f.track)
        if stream not in self.tracks:
            lkey = landmark_key(FEATURE_BASE + len(self.tracks))
            self.tracks[stream] = lkey
            config = self.config
            depth, sigma = f.depth_prior or (config.feature_depth, config.feature_depth_sigma)
            ray = np.array([(ideal[0] - cam.cx) / cam.fx, (ideal[1] - cam.cy) / cam.fy, 1.0])
            p_body = f.body_T_sensor.transformFrom(ray * depth)
            rng = float(np.linalg.norm(p_body))
            self.landmark_guess[lkey] = ("from", f.robot, k, p_body / rng, rng)
            self.point_priors.append((lkey, sigma, time))
        noise = robust_noise(gtsam.noiseModel.Isotropic.Sigma(2, f.pixel_sigma), self.kernel)
        factor = gtsam.GenericProjectionFactorCal3_S2(
            gtsam.Point2(*ideal),
            noise,
            pose_key(f.robot, k),
            self.tracks[stream],
            self.calibrations[id(cam)],
            f.body_T_sensor,
        )
        made = [(time, factor, "projection")]
        self.made.factors += made
        return made


def marker_factors(
    run: TeamRun,
    config: GraphConfig,
    r: int,
    k: int,
    time: float,
    observation,
    E: gtsam.Pose3,
    known: dict,
) -> SectionFactors:
    """The marker pixels of one candidate set of a static target as projection factors on robot r's
    pose k (sensor at body_T_sensor E) and the target's marker points; a marker point not in `known`
    enters once, with a prior of the target's pose prior carried to it (H P H^T, H = d(T m)/dT = [-R
    [m]x, R])."""
    out = SectionFactors()
    ti = observation.target
    target = run.robots[ti]
    T = target.initial_pose
    R = T.rotation().matrix()
    keys = []
    for m in observation.pixels.markers:
        key = marker_key(ti, int(m))
        keys.append(key)
        if key not in known and key not in out.marker_points:
            local = np.asarray(target.markers[int(m)], float)
            H = np.hstack([-R @ skew(local), R])
            cov = H @ cov6(config.static_sigma) @ H.T + np.eye(3) * 1e-12
            out.marker_points[key] = T.transformFrom(local)
            prior = gtsam.PriorFactorPoint3(
                key, out.marker_points[key], gtsam.noiseModel.Gaussian.Covariance(cov)
            )
            out.factors.append((time, prior, "marker_prior"))
    out.merge(_projections(run, config, r, k, time, observation, E, keys))
    return out


def moving_marker_factors(
    run: TeamRun,
    config: GraphConfig,
    r: int,
    k: int,
    kt: int,
    index: int,
    time: float,
    observation,
) -> SectionFactors:
    """The marker pixels of one candidate set of a moving target: per marker one point of that set
    (`keys.frame_marker_key`), held on the target's pose kt by a BearingRangeFactor3D to its layout
    position (std `marker_sigma`) and projected into the observer's pose k; the points' initial
    values come from the target's pose (`frame_points`)."""
    out = SectionFactors()
    ti = observation.target
    target = run.robots[ti]
    keys = []
    for m in observation.pixels.markers:
        key = frame_marker_key(index, int(m))
        local = np.asarray(target.markers[int(m)], float)
        distance = float(np.linalg.norm(local))
        sigma = config.marker_sigma
        noise = gtsam.noiseModel.Diagonal.Sigmas(
            np.array([sigma / max(distance, sigma)] * 2 + [sigma])
        )
        out.factors.append(
            (
                time,
                gtsam.BearingRangeFactor3D(
                    pose_key(ti, kt),
                    key,
                    gtsam.Unit3(local + (distance < sigma) * sigma),
                    distance,
                    noise,
                ),
                "marker_layout",
            )
        )
        out.frame_points.append((key, ti, kt, local))
        keys.append(key)
    out.merge(_projections(run, config, r, k, time, observation, observation.body_T_sensor, keys))
    return out


def _projections(run, config, r, k, time, observation, E, keys) -> SectionFactors:
    """One GenericProjectionFactorCal3_S2 per marker pixel of `observation` on robot r's pose k
    (sensor at body_T_sensor E) and the marker point `keys[i]` (robust kernel 'projection'); a
    pixel that does not undistort is a counted skip `bad_pixel`."""
    out = SectionFactors()
    pix = observation.pixels
    cam = pix.camera
    K = gtsam.Cal3_S2(cam.fx, cam.fy, 0.0, cam.cx, cam.cy)
    noise = robust_noise(
        gtsam.noiseModel.Isotropic.Sigma(2, pix.pixel_sigma), config.kernels.kernel("projection")
    )
    target = run.robots[observation.target]
    for m, uv, key in zip(pix.markers, pix.pixels, keys):
        ideal = _ideal_pixel(cam, uv)
        if ideal is None:
            out.skips.add(
                "bad_pixel",
                f"robot {run.robots[r].name}: marker {int(m)} of {target.name} at "
                f"{observation.time}: pixel {np.asarray(uv).tolist()} does not undistort",
            )
            continue
        out.factors.append(
            (
                time,
                gtsam.GenericProjectionFactorCal3_S2(
                    gtsam.Point2(*ideal), noise, pose_key(r, k), key, K, E
                ),
                "marker",
            )
        )
    return out


def _ideal_pixel(camera, pixel: np.ndarray):
    """The pixel as an ideal pinhole camera sees it (lens distortion removed), None if it
    does not undistort."""
    if not camera.dist:
        return np.asarray(pixel, float)
    bearing, ok = camera.pixel_to_bearing(np.asarray(pixel, float)[None])
    if not ok[0]:
        return None
    b = bearing[0]
    return np.array([camera.fx * b[0] / b[2] + camera.cx, camera.fy * b[1] / b[2] + camera.cy])
