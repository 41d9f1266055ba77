"""`ScanLinks`: the inter-robot scan registration of `live.events.EventGraph` (seed 004, Sec.
II-C / III: P3P initializes ICP, which fuses the ground and ceiling robots' maps) as
scan-matching factors, made causal; a rejected registration is counted, never guessed
(docs/design_team_graph.md, "Scan registration")."""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.keys import pose_key
from graphloc.live.event_placement import initial_upto, seed_robot
from graphloc.pipelines.team_graph.config import adjoint_cov, cov6
from graphloc.pipelines.team_graph.motion import compose_steps


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
            scan_a = _nearest_scan(self.mine[a], scan_b.time)
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
        """Robot b's scan nearest its guess (node, time, body pose, 6x6 covariance) registered
        onto robot a's scan at the same time (`mapping.robust_registration.robust_register` from
        the hint and its covariance, with the acceptance checks): (factor time, a
        BetweenFactorPose3 with the registration's covariance, {b's node: (a, a's node, rel)},
        (scan times)), or None (a rejection in `reasons`, else counted). `prepared`: scan path
        -> PreparedCloud, filled here."""
        events, config, robots = self.events, self.config, self.run.robots
        nearest, node_times = events.clock.nearest, events.clock.node_times
        step_rel, skips = events.graph.step_rel, events.skips
        k_tent, t_tent, X_tent, cov_tent = guess
        scan_b = _nearest_scan(self.mine[b], t_tent)
        scan_a = _nearest_scan(self.mine[a], scan_b.time)
        name = f"robots {robots[a].name} / {robots[b].name}"
        if abs(scan_a.time - scan_b.time) > self.tolerance:
            skips.add("scan_match_rejected", f"{name}: no scans at a common time near {t_tent}")
            return None
        ka, kb = nearest(a, scan_a.time), nearest(b, scan_b.time)
        if ka < 0 or kb < 0:
            skips.add("no_pose_at_time", f"{name}: scans at {scan_b.time} have no poses")
            return None
        if kb >= k_tent:
            step, step_cov = compose_steps(step_rel[b], k_tent, kb, config)
        else:
            back, step_cov = compose_steps(step_rel[b], kb, k_tent, config)
            step = back.inverse()
        X_b = X_tent.compose(step)
        cov_b = adjoint_cov(step.inverse(), cov_tent) + step_cov
        E_a, E_b = scan_a.body_T_sensor, scan_b.body_T_sensor
        hint = self._pose(a, ka).compose(E_a).inverse().compose(X_b.compose(E_b))  # T_sa_sb
        hint_cov = adjoint_cov(E_b.inverse(), cov_b)
        # Open3D loads only for runs that register scans (`graphloc smooth` of other runs skips it)
        from graphloc.mapping.io import read_scan
        from graphloc.mapping.acceptance import AcceptanceConfig
        from graphloc.mapping.registration import RegistrationConfig, prepare
        from graphloc.mapping.robust_registration import robust_register

        cfg = config.registration or RegistrationConfig()
        acceptance = config.acceptance or AcceptanceConfig()
        try:
            # the scans as the reader kept them (thinned to the point budget, read again quietly)
            for scan in (scan_b, scan_a):
                if scan.path not in prepared:
                    prepared[scan.path] = prepare(read_scan(scan.path, warn=False)[0], cfg)
            source, target = prepared[scan_b.path], prepared[scan_a.path]
        except (OSError, ValueError) as exc:
            raise ValueError(f"{name}: scan registration: {exc}") from None
        decision = robust_register(
            source, target, hint.matrix(), 0.5 * (hint_cov + hint_cov.T), cfg, acceptance
        )
        if not decision.accepted:
            reasons.append(
                f"{name}: scans at {scan_b.time}: registration not accepted "
                f"({'; '.join(decision.reasons)})"
            )
            return None
        T = gtsam.Pose3(decision.registration.transformation)  # T_sa_sb
        rel = E_a.compose(T).compose(E_b.inverse())  # body_a_T_body_b
        cov = adjoint_cov(E_b, decision.covariance)
        noise = gtsam.noiseModel.Gaussian.Covariance(0.5 * (cov + cov.T))
        factor = gtsam.BetweenFactorPose3(pose_key(a, ka), pose_key(b, kb), rel, noise)
        t = max(node_times[a][ka], node_times[b][kb], t_tent)
        return t, factor, {kb: (a, ka, rel)}, (scan_a.time, scan_b.time)

    def _pose(self, r: int, k: int):
        """Robot r's initial pose at node k, carried along its steps up to it."""
        robot = self.events.robots[r]
        if robot.initial_done <= k:
            initial_upto(self.events.graph, self.config, [robot], float(robot.times[k]))
        return self.events.graph.initial[pose_key(r, k)]

    def _factor(self, t: float, a: int, b: int, factor) -> None:
        """A registration's factor, at its time or, made at a placement, with the placing step
        (the later of the two robots' first placed pose times)."""
        anchored = self.events.graph.anchored_from
        t = max(t, anchored.get(a, -np.inf), anchored.get(b, -np.inf))
        self.count += 1
        self.events.pending.add(t, (5, self.count), factor, "scan_match")


def _nearest_scan(scans: list, t: float):
    return min(scans, key=lambda s: abs(s.time - t))
