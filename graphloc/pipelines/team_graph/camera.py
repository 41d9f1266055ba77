"""Feature tracks (seed 003 II-B: KLT) as projection factors on landmark variables, one per
track (seed 003 eq. 14), with the seed's weak prior on each point: on the first ray at the
camera's `feature_depth` with std `feature_depth_sigma` (seed III: the EKF's KLT points start
at the background distance with a large covariance). Explicit landmarks rather than
SmartProjectionPose3Factor: a smart factor grows with its track, and `Session` (append-only
`add`) cannot tell iSAM2 that an added factor changed; the prior keeps every landmark determined
from its first pixel on (an undamped iSAM2 step can push a point behind a camera, where the
projection gives no information)."""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.factors.robust import robust_noise
from graphloc.io import SkipReport
from graphloc.keys import landmark_key, pose_key
from graphloc.pipelines.team_graph.config import FEATURE_BASE, GraphConfig
from graphloc.pipelines.team_graph.motion import Timeline
from graphloc.run import TeamRun


def feature_factors(
    run: TeamRun,
    config: GraphConfig,
    timeline: Timeline,
    factors: list,
    skips: SkipReport,
    landmark_guess: dict,
    point_priors: list,
) -> int:
    """Every usable feature pixel as a GenericProjectionFactorCal3_S2 (robust kernel
    'projection'); a new track adds its landmark's guess ('from' the first pose, on the first
    ray at the depth prior) to `landmark_guess` and (key, sigma, time) to `point_priors` (the
    prior is placed at the guess once the poses' initial values exist). Returns the number of
    tracks."""
    node_times, nearest = timeline.node_times, timeline.nearest
    kernel = config.kernels.kernel("projection")
    tracks: dict = {}
    calibrations: dict = {}
    for f in run.features:
        k = nearest(f.robot, f.time)
        if k < 0:
            skips.add(
                "no_pose_at_time",
                f"robot {run.robots[f.robot].name}: feature track {f.track} at {f.time} has no "
                f"pose within the sync tolerance",
            )
            continue
        cam = f.camera
        if id(cam) not in calibrations:
            calibrations[id(cam)] = gtsam.Cal3_S2(cam.fx, cam.fy, 0.0, cam.cx, cam.cy)
        ideal = _ideal_pixel(cam, f.pixel)
        if ideal is None:
            skips.add(
                "bad_pixel",
                f"robot {run.robots[f.robot].name}: feature track {f.track} at {f.time}: pixel "
                f"{f.pixel.tolist()} does not undistort",
            )
            continue
        key = pose_key(f.robot, k)
        stream = (f.robot, f.track)
        if stream not in tracks:
            lkey = landmark_key(FEATURE_BASE + len(tracks))
            tracks[stream] = lkey
            depth, sigma = f.depth_prior or (config.feature_depth, config.feature_depth_sigma)
            ray = np.array([(ideal[0] - cam.cx) / cam.fx, (ideal[1] - cam.cy) / cam.fy, 1.0])
            p_body = f.body_T_sensor.transformFrom(ray * depth)
            rng = float(np.linalg.norm(p_body))
            landmark_guess[lkey] = ("from", f.robot, k, p_body / rng, rng)
            point_priors.append((lkey, sigma, node_times[f.robot][k]))
        noise = robust_noise(gtsam.noiseModel.Isotropic.Sigma(2, f.pixel_sigma), kernel)
        factors.append(
            (
                node_times[f.robot][k],
                gtsam.GenericProjectionFactorCal3_S2(
                    gtsam.Point2(*ideal),
                    noise,
                    key,
                    tracks[stream],
                    calibrations[id(cam)],
                    f.body_T_sensor,
                ),
                "projection",
            )
        )
    return len(tracks)


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
