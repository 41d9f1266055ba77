"""Initial poses of robots nothing else places, from their bearings (seed 000,
000_05137a0a9c449be3.txt): three static robots by mutual bearings (Sec. III-A,
`place_by_mutual_bearings`) and a robot resected by P3P on its bearings of three placed static
robots (Sec. IV, `resection_candidates`). Initial values only: the bearings are factors."""

from __future__ import annotations

from itertools import combinations

import gtsam
import numpy as np

from graphloc.geometry.p3p import solve_p3p
from graphloc.run import TeamRun
from graphloc.vision.mutual import localize_three_bearings

RESECTION_SETS = 3  # a resected robot's solve starts from the P3P candidates of its first sets


def _bearings(run: TeamRun) -> tuple[dict, dict]:
    """(observer, target) -> unit direction in the observer's BODY frame (the first row of
    each pair), and {a, b} -> range [m] for robot-to-robot ranges (either direction)."""
    bearing, ranges = {}, {}
    for m in run.points:
        if m.target < 0:
            continue
        if m.kind in ("bearing", "range_bearing"):
            d = m.body_T_sensor.rotation().rotate(np.asarray(m.direction, float))
            bearing.setdefault((m.robot, m.target), np.asarray(d))
        if m.kind in ("range", "range_bearing"):
            ranges.setdefault(frozenset((m.robot, m.target)), m.range)
    return bearing, ranges


def place_by_mutual_bearings(run: TeamRun, placed: dict) -> dict:
    """Static robots without an initial pose placed by mutual bearings with a placed static
    robot (module docstring). placed: robot -> world_T_body of robots already placed (static
    ones with a known pose). Returns robot -> world_T_body for the robots placed here."""
    bearing, ranges = _bearings(run)
    static = [r for r, robot in enumerate(run.robots) if robot.static]
    out: dict = {}
    for trio in combinations(static, 3):
        known = [r for r in trio if r in placed or r in out]
        if len(known) != 1 or not all((i, j) in bearing for i in trio for j in trio if i != j):
            continue
        pair = next((p for p in combinations(trio, 2) if frozenset(p) in ranges), None)
        if pair is None:
            continue
        order = [*pair, next(r for r in trio if r not in pair)]
        u = np.full((1, 3, 3, 3), np.nan)
        for a, i in enumerate(order):
            for b, j in enumerate(order):
                if i != j:
                    u[0, a, b] = bearing[(i, j)]
        res = localize_three_bearings(u, ranges[frozenset(pair)])
        if not res.ok[0]:
            continue
        # res: pose of order[j] in order[0]'s frame; into the world through the placed robot
        k = known[0]
        world_T_k = placed[k] if k in placed else out[k]
        local = [res.pose3(0, 1, j + 1) for j in range(3)]
        world_T_0 = world_T_k.compose(local[order.index(k)].inverse())
        for j, rr in enumerate(order):
            if rr != k:
                out[rr] = world_T_0.compose(local[j])
    return out


def resection_candidates(run: TeamRun, r: int, positions: dict, sets: int) -> list:
    """Robot r's candidate world_T_body poses from P3P on its bearings, at each of the first
    `sets` times it sees three placed static robots (robot -> (3,) world position):
    [(time, world_T_body), ...], empty if it never does. One snapshot's P3P may miss the
    genuine pose (noise pushes it past the reprojection check near a degenerate configuration),
    so the later snapshots' candidates are starts too."""
    rows: dict = {}
    for m in run.points:
        if m.robot == r and m.kind == "bearing" and m.target in positions:
            d = m.body_T_sensor.rotation().rotate(np.asarray(m.direction, float))
            rows.setdefault(m.time, {}).setdefault(m.target, np.asarray(d))
    times = [t for t in sorted(rows) if len(rows[t]) >= 3][:sets]
    out = []
    for t in times:
        targets = sorted(rows[t])[:3]
        f = np.array([rows[t][j] for j in targets])
        X = np.array([positions[j] for j in targets])
        cand = solve_p3p(f[None], X[None])
        out += [
            (t, gtsam.Pose3(gtsam.Rot3(cand.R_wc[0, c]), cand.t_wc[0, c]))
            for c in np.flatnonzero(cand.valid[0])
        ]
    return out
