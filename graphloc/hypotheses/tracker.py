"""HypothesisTracker: multi-hypothesis inference over per-frame P3P candidate mixtures with a
bounded bank of Gaussian tracks (seed 000 Sec. V: belief over the up-to-four P3P solutions,
commit at belief 0.95, relocalize when the committed solution loses support; seed 004
Sec. II-C: the same question with odometry). Per frame: predict every track by the odometry,
score every (track, candidate) pair by a Student-t innovation, one child per candidate from
its best parent (a 2-pose window, `window`), prune to K tracks; commit a track whose posterior
passes `commit_threshold` without its strongest single update. The derivation and the design:
docs/design_algorithms.md, "The hypothesis tracker".
"""

from __future__ import annotations

import math

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.hypotheses import se3
from graphloc.hypotheses.config import TrackerConfig
from graphloc.hypotheses.track import (
    Track,
    capped_candidate_covariances,
    fit_score,
    log_determinants,
)
from graphloc.hypotheses.window import window_updates
from graphloc.seams import Decision, Odometry, check_frame

_sum = np.add.reduce
# P.reshape(36) @ _POSITION_TRACE: the trace of the position block of a 6x6 covariance
_POSITION_TRACE = np.zeros(36)
_POSITION_TRACE[[21, 28, 35]] = 1.0
_EMPTY_R, _EMPTY_T, _EMPTY_P = np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 6, 6))


class HypothesisTracker:
    """Bounded multi-hypothesis tracker over P3P candidate mixtures (see module docstring).

    tracker = HypothesisTracker(TrackerConfig(max_hypotheses=8))
    d0 = tracker.update(candidates_0)             # first frame: no odometry
    d1 = tracker.update(candidates_1, odometry_1)  # Odometry(relative, covariance)
    d1.probabilities, d1.committed, d1.pose

    The live tracks are arrays (rotations, translations, covariances, log-weights, ids,
    candidates, misses), one row per track; `tracks` gives them as `Track`s.
    """

    def __init__(self, config: TrackerConfig = TrackerConfig()):
        self.config = config
        self._set_tracks([])
        self._next_id = 0
        self._committed_id: int | None = None
        self._logit: dict[int, float] = {}  # track id -> posterior log-odds after the last update
        self._max_gain: dict[int, float] = {}  # track id -> largest log-odds gain of one update
        self._last_time: float | None = None

    @property
    def tracks(self) -> list[Track]:
        """The live tracks (copies), in the tracker's order."""
        return [
            Track(gtsam.Pose3(gtsam.Rot3(R), t), P.copy(), lw, i, c, m)
            for R, t, P, lw, i, c, m in zip(
                self._R,
                self._t,
                self._P,
                self._logw.tolist(),
                self._ids,
                self._cand,
                self._misses,
            )
        ]

    def _set_tracks(self, tracks: list[Track]) -> None:
        self._R = np.array([t.mean.rotation().matrix() for t in tracks]).reshape(-1, 3, 3)
        self._t = np.array([t.mean.translation() for t in tracks]).reshape(-1, 3)
        self._P = np.array([t.cov for t in tracks], dtype=float).reshape(-1, 6, 6)
        self._logw = np.array([t.logw for t in tracks], dtype=float)
        self._ids = [t.track_id for t in tracks]
        self._cand = [t.candidate for t in tracks]
        self._misses = [t.misses for t in tracks]

    @property
    def num_hypotheses(self) -> int:
        return len(self._ids)

    @property
    def committed_track(self) -> int | None:
        return self._committed_id

    def update(self, candidates: CandidateSet, odometry: Odometry | None = None) -> Decision:
        first = not self._ids and self._last_time is None
        check_frame(candidates, odometry, first, self._last_time, "HypothesisTracker.update")
        cov = capped_candidate_covariances(candidates, self.config)
        logw_c = np.log(np.maximum(candidates.weights(), 1e-300))
        if not self._ids:
            log_determinants(cov, candidates, self.config)  # the candidates' check
            keep = np.argsort(-logw_c, kind="stable")[: self.config.max_hypotheses]
            ids = list(range(self._next_id + 1, self._next_id + 1 + len(keep)))
            self._next_id += len(keep)
            self._R, self._t, self._P = candidates.R[keep], candidates.t[keep], cov[keep]
            self._logw = logw_c[keep]
            self._ids, self._cand, self._misses = ids, keep.tolist(), [0] * len(keep)
        else:  # check_frame has required odometry for every frame after the first
            self._step(candidates, cov, logw_c, odometry)
        self._last_time = candidates.time
        if len(self._logw):
            self._logw = self._logw - np.logaddexp.reduce(self._logw)
        return self._decide(len(candidates))

    # ---- one frame ---------------------------------------------------------------------------
    def _step(
        self, candidates: CandidateSet, cov: np.ndarray, logw_c: np.ndarray, odometry: Odometry
    ) -> None:
        cfg = self.config
        u = odometry.relative
        uR, ut = u.rotation().matrix(), u.translation()
        ad = u.inverse().AdjointMap()
        logw_h = self._logw
        H, J = len(logw_h), len(candidates)
        # predict every track: x- = x u, P- = Ad(u^-1) P Ad(u^-1)^T + Q
        pred_R = self._R @ uR
        pred_t = self._R @ ut + self._t
        P_pred = ad @ self._P @ ad.T + odometry.covariance

        # (h, j) Gaussian log-likelihoods, rows 0..H-1 of `cols` (row H: the birth); cheap
        # Euclidean pre-gate, then the Mahalanobis gate
        cols = np.full((H + 1, J), -np.inf)
        if J:
            c_mean = _sum(cov, 0) / J
            d = pred_t[:, None, :] - candidates.t[None, :, :]
            var_bound = (P_pred.reshape(H, 36) @ _POSITION_TRACE)[:, None] + (
                cov.reshape(J, 36) @ _POSITION_TRACE
            )
            gated = _sum(d * d, 2) <= cfg.gate * var_bound
            hs, js = np.nonzero(gated)
        else:
            c_mean = np.diag([cfg.default_sigmas[0] ** 2] * 3 + [cfg.default_sigmas[1] ** 2] * 3)
            hs = js = np.zeros(0, dtype=int)
        n_pairs = len(hs)
        S = P_pred[hs] + cov[js]
        # log-determinants of the candidates (their positive-definiteness check), the pairs'
        # innovation covariances, P- + C_mean (Occam factor of a coasting track, below) and
        # C_mean, in one batched call
        logdets = log_determinants(
            np.concatenate([cov, S, P_pred + c_mean, c_mean[None]]), candidates, cfg
        )
        logdet_c = logdets[:J]
        if n_pairs:  # the pairs' innovations Log((x u)^-1 z)
            RT = pred_R[hs].transpose(0, 2, 1)
            inn_R = RT @ candidates.R[js]
            inn_t = (RT @ (candidates.t[js] - pred_t[hs])[:, :, None])[:, :, 0]
            e, jr_inv, ad_e = se3.log(inn_R, inn_t, jacobian=True)
            maha = (e[:, None, :] @ np.linalg.solve(S, e[:, :, None]))[:, 0, 0]
            # log det(I + P- C^-1) = log det S - log det C
            ll = fit_score(maha, cfg.student_dof) - 0.5 * (logdets[J : J + n_pairs] - logdet_c[js])
            ll[maha > cfg.gate] = -np.inf
            cols[hs, js] = logw_h[hs] + logw_c[js] + ll
        cols[H] = math.log(cfg.birth_probability) + logw_c
        complete = J >= cfg.full_count
        log_miss = math.log(cfg.miss_probability_full if complete else 1.0 / cfg.full_count)
        if J and not complete:
            cols[:H] += math.log(J / cfg.full_count)

        # children: one per candidate (merged over parents + birth), plus one coasting hypothesis
        # per track (its coasting copies merged); every candidate keeps a child (so that a birth
        # can always take over: relocalization), coasting tracks fill the remaining slots
        child_lw = np.logaddexp.reduce(cols, axis=0).tolist()
        child_parent = cols.argmax(axis=0).tolist()
        # a coasting track pays the Occam factor of an average consistent association,
        # 1/2 log det(I + P- C_mean^-1), so that a miss is neutral w.r.t. associating
        coast_lw = (logw_h + log_miss - 0.5 * (logdets[-1 - H : -1] - logdets[-1])).tolist()
        coast: dict[int, tuple[float, int]] = {}  # track id -> (merged log-weight, best hypothesis)
        lw_h = logw_h.tolist()
        for h, (track_id, misses) in enumerate(zip(self._ids, self._misses)):
            if misses >= cfg.max_misses:
                continue
            if track_id in coast:
                merged, best = coast[track_id]
                coast[track_id] = (
                    float(np.logaddexp(merged, coast_lw[h])),
                    best if lw_h[best] >= lw_h[h] else h,
                )
            else:
                coast[track_id] = (coast_lw[h], h)
        kept = sorted(range(J), key=lambda j: -child_lw[j])[: cfg.max_hypotheses]
        coasting = sorted(coast.values(), key=lambda e: -e[0])[: cfg.max_hypotheses - len(kept)]

        # the kept children's windows (tracker.py step 3; graphloc.hypotheses.window)
        updates = [j for j in kept if child_parent[j] != H]
        win_R, win_t, win_P = _EMPTY_R, _EMPTY_T, _EMPTY_P
        if updates:
            parents = [child_parent[j] for j in updates]
            # the pairs' rows: np.nonzero's row-major order
            k = (np.cumsum(gated) - 1)[np.array(parents) * J + updates]
            win_R, win_t, win_P, _ = window_updates(
                (self._P[parents], odometry.covariance, cov[updates]),
                ad,
                (candidates.R[updates], candidates.t[updates]),
                (inn_R[k], inn_t[k], e[k], jr_inv[k] - ad_e[k]),
                cfg.gn_iterations,
            )
            if cfg.student_scale and cfg.student_dof < math.inf:
                scale = (cfg.student_dof + maha[k]) / (cfg.student_dof + 6.0)
                win_P = win_P * scale[:, None, None]

        # the new tracks, rows of [predictions (H) | candidates (J) | windows]
        rows, logw, ids, cands, misses = [], [], [], [], []
        window = H + J
        for j in kept:
            parent = child_parent[j]
            logw.append(child_lw[j])
            cands.append(j)
            misses.append(0)
            if parent == H:  # birth
                self._next_id += 1
                rows.append(H + j)
                ids.append(self._next_id)
            else:
                rows.append(window)
                window += 1
                ids.append(self._ids[parent])
        for lw, h in coasting:
            rows.append(h)
            logw.append(lw)
            ids.append(self._ids[h])
            cands.append(-1)
            misses.append(self._misses[h] + 1)
        self._R = np.concatenate([pred_R, candidates.R, win_R])[rows]
        self._t = np.concatenate([pred_t, candidates.t, win_t])[rows]
        self._P = np.concatenate([P_pred, cov, win_P])[rows]
        self._logw = np.array(logw)
        self._ids, self._cand, self._misses = ids, cands, misses

    def _decide(self, num_candidates: int) -> Decision:
        cfg = self.config
        probs = np.zeros(num_candidates)
        track_prob: dict[int, float] = {}
        weights = np.exp(self._logw).tolist()
        for p, track_id, candidate in zip(weights, self._ids, self._cand):
            if candidate >= 0:
                probs[candidate] += p
            track_prob[track_id] = track_prob.get(track_id, 0.0) + p
        # log-odds floored at the uninformed 1/full_count: a relocalization birth's tiny prior is
        # not evidence against it to be made up after its decisive update is held out
        floor = -math.log(cfg.full_count - 1.0) if cfg.full_count > 1 else -math.inf
        logit = {
            i: max(floor, math.log(p) - math.log1p(-min(p, 1.0 - 1e-15)) if p > 0.0 else floor)
            for i, p in track_prob.items()
        }
        gain = {
            i: max(self._max_gain.get(i, 0.0), lg - self._logit[i]) if i in self._logit else 0.0
            for i, lg in logit.items()
        }
        self._logit, self._max_gain = logit, gain
        relocalized = False
        if (
            self._committed_id is not None
            and track_prob.get(self._committed_id, 0.0) < cfg.release_threshold
        ):
            self._committed_id = None
            relocalized = True
        if self._committed_id is None and track_prob:
            best_id = max(track_prob, key=track_prob.get)
            held_out = logit[best_id] - (gain[best_id] if cfg.robust_commit else 0.0)
            if held_out >= math.log(cfg.commit_threshold / (1.0 - cfg.commit_threshold)):
                self._committed_id = best_id
        if not self._ids:
            return Decision(probs, -1, False, None, relocalized)
        rows = range(len(self._ids))
        committed = -1
        if self._committed_id is not None:
            rows = [h for h in rows if self._ids[h] == self._committed_id]
            committed = next((self._cand[h] for h in rows if self._cand[h] >= 0), -1)
        best = max(rows, key=self._logw.tolist().__getitem__)
        pose = gtsam.Pose3(gtsam.Rot3(self._R[best]), self._t[best])
        return Decision(probs, committed, self._committed_id is not None, pose, relocalized)
