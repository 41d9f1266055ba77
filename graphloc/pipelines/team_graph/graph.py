"""`TeamGraph`: a team run as one graph, its factors grouped in time steps with initial values
(what `graphloc.live.builder.build_live` grows row by row and `solve` takes); `SectionFactors`,
what one section makes; and the helpers its builders share."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from graphloc.textio import SkipReport
from graphloc.keys import pose_key
from graphloc.factors.mixture import MaxMixture
from graphloc.pipelines.team_graph.config import COARSE_PRECISION, GraphConfig
from graphloc.run import TeamRun


@dataclass
class SectionFactors:
    """What a section of the graph makes: factors (time of the newest pose, factor, type), the
    skips it counted, a static target's new marker points (key -> world position: their
    initial values) and a moving target's per-set points ((key, target, node, body-frame
    position) each: their initial values come from the target's pose)."""

    factors: list = field(default_factory=list)
    skips: SkipReport = field(default_factory=SkipReport)
    marker_points: dict = field(default_factory=dict)
    frame_points: list = field(default_factory=list)

    def merge(self, other: "SectionFactors") -> None:
        """`other`'s factors, skips and points after these."""
        self.factors += other.factors
        self.skips.merge(other.skips)
        self.marker_points.update(other.marker_points)
        self.frame_points += other.frame_points


@dataclass
class TeamGraph:
    """The run as one graph, step by step: steps[i] = (time, [(factor, type), ...]); node
    times per robot; dead-reckoning / decided initial values; factor type counts."""

    run: TeamRun
    config: GraphConfig
    node_times: list
    # per robot (relative Pose3 from node k-1, covariance) for k >= 1 (None: unknown)
    step_rel: list
    initial: dict = field(default_factory=dict)  # key -> Pose3 (initial guess)
    steps: list = field(default_factory=list)
    factor_types: list = field(default_factory=list)
    decisions: list = field(default_factory=list)
    # robot -> first node time the online graph may hold it
    anchored_from: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)
    skips: SkipReport = field(default_factory=SkipReport)
    precision: float = COARSE_PRECISION  # run_precision(run)
    links: dict = field(default_factory=dict)  # observer pose key -> (target key, (K,4,4))
    # other initial values the batch solve starts from too (key -> value, over `initial`): one
    # per candidate of a pixel stream's first set or of a resected robot's first sets
    # (`live.event_placement.alternative_placements`)
    alternatives: list = field(default_factory=list)
    # those of robots placed by the tracker's guess (it never decided their stream): the online
    # solve starts from these too
    guessed_alternatives: list = field(default_factory=list)
    # a moving target's marker point of one set -> (the target's pose key, its body-frame
    # position): online predicts the point from the pose's estimate
    frame_points: dict = field(default_factory=dict)
    # an offset sensor's pose variable -> (its body pose key, body_T_sensor): its value is the
    # body pose's composed with the extrinsics (`points.SensorPoses`)
    sensor_poses: dict = field(default_factory=dict)
    # the graph holds feature tracks or max-mixtures (iSAM2's settings for camera graphs,
    # `GraphConfig.session_config`), known from the run's tables before its rows
    camera: bool = False
    # the time of the node each alternative (each guessed alternative) was placed at: the
    # node of its own candidate set; the solve does not drop a hypothesis before that node's
    # step (`side_by_side.SideBySide`): earlier steps hold another snapshot's pose, which its start
    # only carried along
    alternative_times: list = field(default_factory=list)
    guessed_alternative_times: list = field(default_factory=list)


def with_sensors(values: dict, sensor_poses: dict) -> dict:
    """`values` (key -> Pose3 / Point3) with the value of every sensor pose whose body pose it
    holds: the body pose composed with the extrinsics (in place; returned)."""
    for key, (body, E) in sensor_poses.items():
        if body in values:
            values[key] = values[body].compose(E)
    return values


def factor_keys(factor) -> list:
    """The variables of a graph item: a gtsam factor or a factor provider (`MaxMixture`)."""
    return list(factor.keys) if isinstance(factor, MaxMixture) else list(factor.keys())


def landmark_initial(initial: dict, lkey: int, guess) -> None:
    """A landmark's initial value into `initial`: a position, or ('from', r, k, direction,
    range) -- along a ray of pose (r, k), once that pose has an initial value."""
    if isinstance(guess, tuple) and guess and guess[0] == "from":
        _, r, k, direction, rng = guess
        if pose_key(r, k) in initial:
            initial[lkey] = initial[pose_key(r, k)].transformFrom(direction * rng)
    else:
        initial[lkey] = np.asarray(guess, dtype=float)


def count_graph(graph: TeamGraph, points, poses: int, **sections) -> None:
    """graph.counts (metrics.json): robots, `poses`, the point section's (`points`: a
    `points.PointBuilder`), the steps and factors by type; `sections`: the candidate and camera
    sections' counts (0 where not given)."""
    types = graph.factor_types
    counts = {
        "robots": len(graph.run.robots),
        "poses": poses,
        "candidate_sets": 0,
        "marker_points": 0,
        "frame_marker_points": len(graph.frame_points),
        "sensor_poses": len(points.sensors.poses),
        "committed_sets": 0,
        "landmark_anchors": points.n_anchor,
        "feature_tracks": 0,
        "steps": len(graph.steps),
        "excluded_by_option": points.excluded,
    }
    counts.update(sections)
    counts.update({f"factors_{name}": types.count(name) for name in sorted(set(types))})
    graph.counts = counts
