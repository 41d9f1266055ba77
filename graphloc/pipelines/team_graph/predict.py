"""Online initial values of new variables (`solve.Pass`): a pose from its robot's latest
estimate and odometry (or resected from a teammate seen through a max-mixture), a moving
target's marker point from its pose's estimate, an offset sensor's pose from its body pose's
(`on_body`), the graph's guess otherwise."""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.keys import decode
from graphloc.pipelines.team_graph.graph import TeamGraph
from graphloc.pipelines.team_graph.motion import compose_steps


def on_body(graph: TeamGraph, key: int, values: gtsam.Values, session, added: set):
    """Online initial value of a variable held on a pose -- a moving target's marker point of
    one set (`TeamGraph.frame_points`) or an offset sensor's pose (`TeamGraph.sensor_poses`) --
    from that pose's value in this step or its current estimate, else the graph's guess."""
    point = key in graph.frame_points
    body, offset = graph.frame_points[key] if point else graph.sensor_poses[key]
    if values.exists(body):
        pose = values.atPose3(body)
    elif body in added:
        pose = session.estimate([body]).atPose3(body)
    else:
        return graph.initial[key]
    return pose.transformFrom(offset) if point else pose.compose(offset)


def predict(graph: TeamGraph, key: int, decoded: tuple, latest: dict, initial: dict | None):
    """Initial value of a new variable: a landmark's guess; a pose from its robot's latest
    estimate composed with the odometry since -- or, where it sees a target of the
    max-mixture route that its own odometry predicts worse than the target's does, resected
    from the target (`_resected`) --, else the graph's initial guess."""
    kind, r, k = decoded  # decode(key)
    if kind != "x":
        return (graph.initial if initial is None else initial)[key]
    if r in latest and latest[r][0] < k:
        k0, pose = latest[r]
        linked = key in graph.links  # only a resection needs the prediction's covariance
        rel, cov = compose_steps(graph.step_rel[r], k0, k, graph.config, covariance=linked)
        if all(s is not None for s in graph.step_rel[r][k0 + 1 : k + 1]):
            predicted = pose.compose(rel)
            if not linked:
                return predicted
            return _resected(graph, key, latest, predicted, np.trace(cov[3:, 3:])) or predicted
    return (graph.initial if initial is None else initial)[key]


def _resected(graph: TeamGraph, key: int, latest: dict, predicted, spread: float):
    """The observer pose `key` from its target's predicted pose through the candidate whose
    rotation is nearest the observer's own prediction (seed 003: a camera without odometry
    re-found from a teammate that stood still; from its previous pose alone, centimetres off,
    the solve can settle in the false candidate's basin), when the target's prediction is
    tighter than the observer's (`spread`: trace of its translation covariance); else None."""
    link = graph.links.get(key)
    if link is None:
        return None
    tkey, relative = link
    _, ti, kt = decode(tkey)
    if ti not in latest or latest[ti][0] > kt:
        return None
    k0, target = latest[ti]
    if k0 < kt:
        step, cov = compose_steps(graph.step_rel[ti], k0, kt, graph.config)
        if np.trace(cov[3:, 3:]) >= spread:
            return None
        target = target.compose(step)
    poses = [target.compose(gtsam.Pose3(T).inverse()) for T in relative]
    angles = [
        np.linalg.norm(gtsam.Rot3.Logmap(predicted.rotation().between(p.rotation()))) for p in poses
    ]
    return poses[int(np.argmin(angles))]
