"""`ScanLinks`: the inter-robot scan registration of `live.events.EventGraph`, made causal
(seed 004, Sec. II-C / III: P3P initializes ICP, which fuses the ground and ceiling robots'
maps); the rule is in docs/design_team_graph.md, "Scan registration"."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graphloc.keys import pose_key
from graphloc.live.event_placement import initial_upto, seed_robot
from graphloc.pipelines.team_graph.config import cov6
from graphloc.pipelines.team_graph.scans import register_pair, scan_near


@dataclass(frozen=True)
class _Scans:
    """What `register_pair` reads of a run: its robots and the scans arrived so far."""

    robots: tuple
    scans: tuple


class ScanLinks:
    """The registrations between an `EventGraph`'s scanning robots (module docstring):
    `scan(obs)` takes a `ScanObservation` as it arrives, `place(robot, tentative)` tries to
    place an unplaced scanning robot from its stream's hypotheses, `pairs(final)` registers the
    common scan times now due; `bound()` is the latest time steps may be emitted up to."""

    def __init__(self, events):
        self.events = events
        self.run, self.config = events.run, events.config
        self.mine: dict = {}  # robot -> its ScanObservations, in arrival order
        self.done: dict = {}  # (a, b) -> b's scans registered onto a so far
        self.used: set = set()  # (scan time of a, of b) of the registrations made
        self.reasons: dict = {}  # robot -> why its placing registrations were refused
        self.tries: dict = {}  # robot -> hypotheses tried
        self.count = 0

    @property
    def tolerance(self) -> float:
        return max(self.config.sync_tolerance, self.config.keyframe_dt / 2)

    def scan(self, obs) -> None:
        self.mine.setdefault(obs.robot, []).append(obs)

    def place(self, b: int, tentative: list | None) -> None:
        """Register unplaced robot b from its hypotheses (`tentative`) onto each placed
        scanning robot; the first accepted places it (its earlier common times follow in
        `pairs`)."""
        robots = self.events.robots
        if b not in self.mine or robots[b].seed is not None or not tentative:
            return
        prepared: dict = {}
        reasons = self.reasons.setdefault(b, [])
        self.tries[b] = self.tries.get(b, 0) + len(tentative)
        for a in self._placed():
            for guess in tentative:
                link = self._register(a, b, guess, reasons, prepared)
                if link is None:
                    continue
                t, factor, via, stamps = link
                kb, (_, ka, rel) = next(iter(via.items()))
                pose = self._pose(a, ka).compose(rel)
                seed_robot(self.events.graph, self.config, robots[b], kb, pose)
                self.used.add(stamps)
                self._factor(t, a, b, factor)
                return

    def pairs(self, final=None) -> None:
        """Register every common scan time of two placed scanning robots whose scans have
        arrived: b's scan once b's pose times are final at it and a's are beyond it by the
        tolerance (`final(robot)`: the robot's pose times before it are final; None: all)."""
        placed = self._placed()
        for i, a in enumerate(placed):
            for b in placed[i + 1 :]:
                self._pairs(a, b, final)

    def bound(self) -> float:
        """Steps up to this time may be emitted: before the first common scan time of two
        placed robots not registered yet."""
        placed, out = self._placed(), np.inf
        for i, a in enumerate(placed):
            for b in placed[i + 1 :]:
                scans = self.mine[b][self.done.get((a, b), 0) :]
                if scans:
                    out = min(out, scans[0].time - self.tolerance - 1e-9)
        return out

    def finish(self, skips) -> None:
        """Every row is in: the remaining common times; a scanning robot never placed counted."""
        self.pairs()
        for b, reasons in self.reasons.items():
            if self.events.robots[b].seed is None and reasons:
                skips.add(
                    "scan_match_rejected",
                    f"robot {self.run.robots[b].name}: no registration from its "
                    f"{self.tries[b]} hypotheses was accepted ({reasons[0]}); left unplaced",
                )

    # ---- internals ----------------------------------------------------------------------------

    def _placed(self) -> list:
        return [r for r in sorted(self.mine) if self.events.robots[r].seed is not None]

    def _pairs(self, a: int, b: int, final) -> None:
        clock, scans = self.events.clock, self.mine[b]
        j = self.done.get((a, b), 0)
        while j < len(scans):
            scan_b = scans[j]
            if final is not None and not (
                scan_b.time + self.tolerance < final(a) and scan_b.time < final(b)
            ):
                break
            j += 1
            kb = clock.nearest(b, scan_b.time)
            if kb < 0:
                continue
            scan_a = scan_near(self._view(a, b), a, scan_b.time)
            if (scan_a.time, scan_b.time) in self.used:  # the pair placed b: a factor already
                continue
            guess = (kb, scan_b.time, self._pose(b, kb), cov6(self.config.scan_hint_sigma))
            reasons: list = []
            link = self._register(a, b, guess, reasons, {})
            if link is None and reasons:
                self.events.skips.add("scan_match_rejected", reasons[0])
            if link is not None and link[3] not in self.used:
                self.used.add(link[3])
                self._factor(link[0], a, b, link[1])
        self.done[(a, b)] = j

    def _register(self, a: int, b: int, guess, reasons: list, prepared: dict):
        events = self.events
        poses = {a: (_Initial(events, a), None)}
        return register_pair(
            self._view(a, b),
            self.config,
            events.clock,
            events.graph.step_rel,
            poses,
            guess,
            a,
            b,
            events.skips,
            reasons,
            prepared,
        )

    def _view(self, a: int, b: int) -> _Scans:
        return _Scans(self.run.robots, tuple(self.mine.get(a, ())) + tuple(self.mine[b]))

    def _pose(self, r: int, k: int):
        return _Initial(self.events, r)[k]

    def _factor(self, t: float, a: int, b: int, factor) -> None:
        """A registration's factor, at its time or, made at a placement, with the placing step
        (the later of the two robots' first placed pose times)."""
        anchored = self.events.graph.anchored_from
        t = max(t, anchored.get(a, -np.inf), anchored.get(b, -np.inf))
        self.count += 1
        self.events.pending.add(t, (5, self.count), factor, "scan_match")


class _Initial:
    """Robot r's initial poses as a list `register_pair` indexes: carried along its steps up
    to the node asked for (`event_placement.initial_upto`)."""

    def __init__(self, events, r: int):
        self.events, self.r = events, r

    def __getitem__(self, k: int):
        events, r = self.events, self.r
        robot = events.robots[r]
        if robot.initial_done <= k:
            initial_upto(events.graph, events.config, [robot], float(robot.times[k]))
        return events.graph.initial[pose_key(r, k)]
