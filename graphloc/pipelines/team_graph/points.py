"""Range, bearing and range-bearing measurements to landmarks and teammates as factors
(`PointBuilder`); a known landmark tied to each observation on its own, an offset bearing on an
auxiliary sensor pose (docs/design_team_graph.md, "Point measurements")."""

from __future__ import annotations


import gtsam
import numpy as np

from graphloc.factors.bearing import (
    bearing_factor,
    bearing_to_point_factor,
    range_factor,
    sensor_tie_factor,
)
from graphloc.factors.range_bearing import (
    known_landmark_factor_3d,
    landmark_factor_3d,
    robot_factor_3d,
)
from graphloc.factors.robust import robust_noise
from graphloc.keys import landmark_key, pose_key, sensor_key
from graphloc.pipelines.team_graph.config import ANCHOR_BASE, GraphConfig
from graphloc.pipelines.team_graph.graph import SectionFactors
from graphloc.run import TeamRun


def _point_factor(m, key, lkey, direction, rng, kernel, E):
    if m.kind == "range_bearing":
        return landmark_factor_3d(
            key, lkey, direction, rng, (m.bearing_sigma, m.bearing_sigma, m.range_sigma), kernel
        )
    if m.kind == "bearing":
        return bearing_to_point_factor(key, lkey, direction, m.bearing_sigma, E, kernel)
    noise = robust_noise(gtsam.noiseModel.Isotropic.Sigma(1, m.range_sigma), kernel)
    if E.translation().any():  # the range from the sensor, not the body origin
        return gtsam.RangeFactorWithTransform3D(key, lkey, float(rng), noise, E)
    return gtsam.RangeFactor3D(key, lkey, float(rng), noise)


def _robot_factor(m, key, tkey, direction, rng, kernel, E):
    if m.kind == "range_bearing":
        return robot_factor_3d(
            key, tkey, direction, rng, (m.bearing_sigma, m.bearing_sigma, m.range_sigma), kernel
        )
    if m.kind == "bearing":
        return bearing_factor(key, tkey, direction, m.bearing_sigma, body_T_camera=E, kernel=kernel)
    identity = np.allclose(E.matrix(), np.eye(4))
    return range_factor(key, tkey, rng, m.range_sigma, None if identity else E, kernel)


class SensorPoses:
    """The auxiliary sensor pose variables of offset bearings: `observer(m, k, t, factors)` gives
    the key a bearing of `m` at robot node k is measured from and the extrinsics left to apply (the
    body pose and m's where the sensor sits at the body origin, else the sensor pose, its tie
    appended to `factors` once); `poses`: sensor key -> (body key, body_T_sensor)."""

    def __init__(self):
        self.poses: dict = {}
        self._slots: dict = {}  # (robot, extrinsics bytes) -> slot

    def observer(self, m, k: int, t: float, factors: list):
        E = m.body_T_sensor
        body = pose_key(m.robot, k)
        if not E.translation().any():
            return body, E
        slot = self._slots.setdefault((m.robot, E.matrix().tobytes()), len(self._slots))
        key = sensor_key(m.robot, slot, k)
        if key not in self.poses:
            self.poses[key] = (body, E)
            factors.append((t, sensor_tie_factor(body, key, E), "sensor_tie"))
        return key, gtsam.Pose3()


def body_frame_points(points: list, at_meas: np.ndarray, at_frame: np.ndarray) -> list:
    """Range-bearing measurements `points` of one robot, each taken at its dead-reckoned planar
    pose `at_meas` (N,3), as (direction (3,), range) in its body frame at the planar pose
    `at_frame` (N,3) of the grid pose it joins."""
    pts = np.array([m.body_T_sensor.transformFrom(m.direction * m.range) for m in points])
    c, s = np.cos(at_meas[:, 2]), np.sin(at_meas[:, 2])
    world = at_meas[:, :2] + np.column_stack(
        [c * pts[:, 0] - s * pts[:, 1], s * pts[:, 0] + c * pts[:, 1]]
    )
    d = world - at_frame[:, :2]
    c, s = np.cos(at_frame[:, 2]), np.sin(at_frame[:, 2])
    local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], pts[:, 2]])
    rng = np.linalg.norm(local, axis=1)
    return [(local[j] / rng[j], float(rng[j])) for j in range(len(points))]


class PointBuilder:
    """The point section, one measurement at a time, in the run's order (`add`): its factors
    and skips (`made`), the landmarks' initial guesses, the anchors made, the measurements the
    options leave out and the offset bearings' sensor poses; the live builders feed it each
    measurement once its poses exist."""

    def __init__(self, run: TeamRun, config: GraphConfig):
        self.run, self.config = run, config
        self.made, self.sensors = SectionFactors(), SensorPoses()
        self.lm_prior = {}
        if config.landmark_priors and run.landmarks_known:
            self.lm_prior = {
                int(i): (p, np.maximum(s, config.landmark_prior_floor))
                for i, p, s in zip(run.landmark_ids, run.landmark_xyz, run.landmark_sigma)
            }
        self.landmark_guess: dict = {}
        self.n_anchor = 0
        self.excluded = 0  # left out by the options (not a data problem: counted, not skipped)

    def used(self, m) -> bool:
        """The options take measurement `m` (else it is counted in `excluded`)."""
        is_lm = m.target < 0
        config = self.config
        if (is_lm and not config.use_landmarks) or (not is_lm and not config.use_inter_robot):
            self.excluded += 1
            return False
        return True

    def add(self, m, k: int, kt: int, node_times: list, corrected=None) -> None:
        """Measurement `m` at robot node k (target node kt; -1: none within the tolerance,
        counted) as a factor; `corrected`: its (direction, range) in the body frame at node k
        (a wheel-odometry robot's range-bearing, `body_frame_points`), None: as measured."""
        run, config, lm_prior = self.run, self.config, self.lm_prior
        factors, skips, landmark_guess = self.made.factors, self.made.skips, self.landmark_guess
        is_lm = m.target < 0
        if k < 0 or (not is_lm and kt < 0):
            skips.add(
                "no_pose_at_time",
                f"robot {run.robots[m.robot].name}: {m.kind} at {m.time} has no pose "
                f"within the sync tolerance",
            )
            return
        key = pose_key(m.robot, k)
        direction, rng = (m.direction, m.range) if corrected is None else corrected
        E = m.body_T_sensor
        t_new = max(node_times[m.robot][k], -np.inf if is_lm else node_times[m.target][kt])
        kernel = config.kernels.kernel("landmark" if is_lm else "inter_robot")
        if m.kind == "range_bearing" and corrected is None:
            p = E.transformFrom(direction * rng)
            direction, rng = p / np.linalg.norm(p), float(np.linalg.norm(p))
        if is_lm and m.kind == "range_bearing" and config.anchor_known_landmarks:
            prior = lm_prior.get(m.landmark)
            if prior is not None:
                f = known_landmark_factor_3d(
                    key,
                    prior[0],
                    float(np.max(prior[1])),
                    direction,
                    rng,
                    (m.bearing_sigma, m.bearing_sigma, m.range_sigma),
                    kernel,
                )
                factors.append((t_new, f, "landmark"))
                return
        if is_lm:
            prior = lm_prior.get(m.landmark)  # None: a landmark estimated (SLAM)
            anchored = prior is not None and config.anchor_known_landmarks
            lkey = landmark_key(ANCHOR_BASE + self.n_anchor if anchored else m.landmark)
            if lkey not in landmark_guess:
                guess = prior[0] if prior is not None else None
                if guess is None and np.isfinite(rng) and np.isfinite(direction).all():
                    guess = ("from", m.robot, k, direction, rng)
                if guess is None:
                    skips.add(
                        "landmark_without_position",
                        f"landmark {m.landmark}: first seen by a {m.kind} only",
                    )
                    return
                landmark_guess[lkey] = guess
                if prior is not None:
                    factors.append(
                        (
                            t_new,
                            gtsam.PriorFactorPoint3(
                                lkey,
                                np.asarray(prior[0], float),
                                gtsam.noiseModel.Diagonal.Sigmas(prior[1]),
                            ),
                            "landmark_prior",
                        )
                    )
            if lkey != landmark_key(m.landmark):
                self.n_anchor += 1
            if m.kind == "bearing":
                key, E = self.sensors.observer(m, k, node_times[m.robot][k], factors)
            factors.append(
                (t_new, _point_factor(m, key, lkey, direction, rng, kernel, E), "landmark")
            )
        else:
            if m.kind == "bearing":
                key, E = self.sensors.observer(m, k, node_times[m.robot][k], factors)
            factors.append(
                (
                    t_new,
                    _robot_factor(m, key, pose_key(m.target, kt), direction, rng, kernel, E),
                    "inter_robot",
                )
            )
