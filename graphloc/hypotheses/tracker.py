"""HypothesisTracker: multi-hypothesis inference over per-frame P3P candidate mixtures with a
bounded bank of Gaussian tracks (seed 000 Sec. V: belief over the up-to-four P3P solutions,
commit at belief 0.95, relocalize when the committed solution loses support; seed 004
Sec. II-C: the same question with odometry).

Design (and why). GTSAM's HybridSmoother keeps one discrete mode per frame in a tree that
grows with every frame; pruning by leaves or marginal thresholds alone either stalls or stops
relinearizing. Here the discrete history is never kept: each hypothesis is a *track* -- "the
genuine candidate at this frame is candidate j, reached along this path" -- carrying a Gaussian
on the camera pose (mean Pose3, 6x6 covariance, GTSAM tangent order) and a log-weight.

Per frame (odometry u with covariance Q, candidates z_j with covariances C_j and weights w_j):
1. predict every track: x- = x u, P- = Ad(u^-1) P Ad(u^-1)^T + Q;
2. score every (track h, candidate j) pair with innovation e = Log(x-^-1 z_j), S = P- + C_j:
       log w_j + f(e^T S^-1 e) - 1/2 log det(I + P- C_j^-1),
   the likelihood of the raw measurement the candidates were solved from: the pixels y are (to
   first order) linear in a candidate's pose with C_j = sigma^2 (A^T A)^-1, so p(y | h) =
   int N(x; x-, P-) p(y | x) dx = sigma^-6 sqrt(det C_j) N(e; 0, S). The Jacobian factor
   sqrt(det C_j) cancels log det C_j inside N: every P3P candidate reprojects the pixels
   exactly, so a candidate is not more likely because its pose covariance is tighter (scored in
   pose space, a pseudo solution with a smaller covariance wins on the log-determinant alone).
   f(m) = -(nu + 6)/2 [log(1 + m/nu) - log(1 + 6/nu)] is a multivariate Student-t (nu = 6; P3P
   errors are heavy-tailed near its danger cylinder; nu = inf gives the Gaussian -1/2 (m - 6)),
   centred at m = 6 = E[chi2_6] so that a consistent association scores ~0 per frame -- the
   scale of the two other options:
   a "miss" keeps a track coasting, scored as an average consistent association (f = 0, Occam
   factor with the frame's mean candidate covariance) times the prior of its solution being
   absent: near the danger cylinder the genuine solution merges with a pseudo one and both
   vanish, sometimes for seconds; with J of 4 solutions present each absent one keeps prior 1/4
   like a present one, with all four present a miss is nearly impossible (miss_probability_full);
   a "birth" starts a track at z_j with log p_birth + log w_j (relocalization after a kidnap or
   a lost track). Candidate covariances are capped at max_candidate_std (linearization trust
   region: near the fold of the P3P map the first-order covariance is meaningless);
3. children: one per candidate, log-sum-exp over all parents and the birth (the posterior
   that j is genuine), state from the best parent updated by a 2-pose fixed-lag window in
   GTSAM: PriorFactorPose3 (parent marginal) + BetweenFactorPose3 (odometry) + the mixture
   component of z_j (`graphloc.factors.mixture.component_factors`); the windows of all
   children of a frame are one graph (disjoint keys) and one Gauss-Newton (both poses of
   every window relinearized), the new covariances are Schur complements of the Hessian's
   diagonal blocks. The innovation being Student-t, so is the posterior (Roth, Ozkan,
   Gustafsson 2013, "A Student's t filter for heavy tailed process and measurement noise"):
   its scale is the Gaussian one times (nu + m) / (nu + 6) -- a surprising frame makes the
   track less certain instead of dragging a confident wrong state into the next frames'
   scores (`student_scale`);
4. prune: every candidate keeps its child (so a birth can always take over), coasting tracks
   (one per track id) fill the remaining slots up to K; normalize.
Decided modes are fixed by construction (the past is marginalized into each track's Gaussian;
`graphloc.pipelines.track_smoothing.track_graph` re-solves a run with its committed modes in a
batch Session), the number of live tracks is <= K and per-frame work is O(K * candidates):
latency and memory do not grow with the run length.

Commit: a track is the lineage of hypotheses through best parents (its id survives frames in
which it coasts). When a track's posterior (summed over its live hypotheses: the child on a
candidate and a coasting copy) passes `commit_threshold` (0.95, seed 000 Sec. VI-B) *without
the single update that raised its log-odds most* (`robust_commit`), it is committed; when it
falls below `release_threshold` the question is re-opened (the `relocalized` flag of that
frame's Decision). Why the held-out update: P3P candidates are heavy-tailed (the genuine
solution is far outside its first-order covariance more often than a Gaussian allows) and on
a sloped ceiling a pseudo solution can follow the odometry for the first few updates (their
motion is well inside the candidates' spread), so the posterior can pass 0.95 on one frame's
noise; a commit now needs the threshold to hold on the evidence of the other updates, i.e. at
least two updates must agree (the seed's own remedy is to wait for motion: 0.3 s before its
first update). The cost, about one more update to the first commit, and the wrong first
commits it removes are measured on held-out seeds by scripts/bench_hypotheses.py
(--seed-offset) and tests/test_hypotheses.py.

Inputs shared with the baselines (graphloc.baselines): per frame a CandidateSet (camera poses
in the world) and, from the second frame on, an `Odometry` (relative camera pose since the
previous frame, in that frame, with covariance).
"""

from __future__ import annotations

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.mixture import candidate_covariances
from graphloc.hypotheses.config import TrackerConfig
from graphloc.hypotheses.track import Track, cap_covariances, fit_score
from graphloc.hypotheses.state import STATE_FIELDS, load_state, save_state
from graphloc.keys import pose_key
from graphloc.seams import Decision, Odometry, check_frame


class HypothesisTracker:
    """Bounded multi-hypothesis tracker over P3P candidate mixtures (see module docstring).

    tracker = HypothesisTracker(TrackerConfig(max_hypotheses=8))
    d0 = tracker.update(candidates_0)             # first frame: no odometry
    d1 = tracker.update(candidates_1, odometry_1)  # Odometry(relative, covariance)
    d1.probabilities, d1.committed, d1.pose
    """

    def __init__(self, config: TrackerConfig = TrackerConfig()):
        self.config = config
        self._tracks: list[Track] = []
        self._next_id = 0
        self._committed_id: int | None = None
        self._logit: dict[int, float] = {}  # track id -> posterior log-odds after the last update
        self._max_gain: dict[int, float] = {}  # track id -> largest log-odds gain of one update
        self._last_time: float | None = None
        self._gn = self._make_gn_params(config)

    @staticmethod
    def _make_gn_params(config: TrackerConfig) -> gtsam.GaussNewtonParams:
        params = gtsam.GaussNewtonParams()
        params.setMaxIterations(int(config.gn_iterations))
        return params

    def __getstate__(self) -> dict:
        """Picklable state (save / resume an online tracker): GaussNewtonParams is rebuilt."""
        state = self.__dict__.copy()
        del state["_gn"]
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._gn = self._make_gn_params(self.config)

    # ---- save / resume as data (no pickle: a loaded file never runs code) ----------------------
    def save(self, path) -> None:
        """Write the tracker's whole state (config, tracks, commit, log-odds) to `path` as a
        versioned JSON file, atomically (`graphloc.hypotheses.state`); `load` resumes it with
        identical decisions."""
        save_state(path, self.config, self._state())

    @classmethod
    def load(cls, path) -> "HypothesisTracker":
        """A tracker `save` wrote. ValueError naming the file and the field on anything else."""
        config, state = load_state(path)
        tracker = cls(config)
        for name, value in state.items():
            setattr(tracker, f"_{name}", value)
        return tracker

    def _state(self) -> dict:
        return {name: getattr(self, f"_{name}") for name in STATE_FIELDS}

    @property
    def num_hypotheses(self) -> int:
        return len(self._tracks)

    @property
    def committed_track(self) -> int | None:
        return self._committed_id

    def update(self, candidates: CandidateSet, odometry: Odometry | None = None) -> Decision:
        first = not self._tracks and self._last_time is None
        check_frame(candidates, odometry, first, self._last_time, "HypothesisTracker.update")
        cov = cap_covariances(
            candidate_covariances(candidates, self.config.default_sigmas),
            self.config.max_candidate_std,
        )
        self._last_time = candidates.time
        logw_c = np.log(np.maximum(candidates.weights(), 1e-300))
        if not self._tracks:
            keep = np.argsort(-logw_c, kind="stable")[: self.config.max_hypotheses]
            poses = candidates.poses()
            self._tracks = [self._birth(poses[j], cov[j], int(j), float(logw_c[j])) for j in keep]
        else:  # check_frame has required odometry for every frame after the first
            self._step(candidates, cov, logw_c, odometry)
        self._normalize()
        return self._decide(len(candidates))

    # ---- one frame ---------------------------------------------------------------------------
    def _birth(self, pose: gtsam.Pose3, cov: np.ndarray, j: int, logw: float) -> Track:
        self._next_id += 1
        return Track(pose, cov.copy(), logw, self._next_id, j)

    def _step(
        self, candidates: CandidateSet, cov: np.ndarray, logw_c: np.ndarray, odometry: Odometry
    ) -> None:
        cfg = self.config
        u = odometry.relative
        ad = u.inverse().AdjointMap()
        preds = [t.mean.compose(u) for t in self._tracks]
        P_pred = (
            np.einsum("ij,hjk,lk->hil", ad, np.stack([t.cov for t in self._tracks]), ad)
            + odometry.covariance
        )
        logw_h = np.array([t.logw for t in self._tracks])
        H, J = len(self._tracks), len(candidates)
        zs = candidates.poses()

        # (h, j) Gaussian log-likelihoods; cheap Euclidean pre-gate, then the Mahalanobis gate
        log_assoc = np.full((H, J), -np.inf)
        maha_hj = np.full((H, J), np.inf)
        # log-determinants of the candidates, of P- + C_mean (Occam factor of a coasting track,
        # below) and of C_mean, in one batched call
        c_mean = (
            cov.mean(axis=0)
            if J
            else np.diag([cfg.default_sigmas[0] ** 2] * 3 + [cfg.default_sigmas[1] ** 2] * 3)
        )
        logdets = np.linalg.slogdet(np.concatenate([cov, P_pred + c_mean, c_mean[None]]))[1]
        logdet_c, logdet_pc, logdet_cm = logdets[:J], logdets[J : J + H], logdets[-1]
        if J:
            pos_pred = np.array([p.translation() for p in preds])
            d2 = np.sum((pos_pred[:, None, :] - candidates.t[None, :, :]) ** 2, axis=2)
            var_bound = (
                np.trace(P_pred[:, 3:, 3:], axis1=1, axis2=2)[:, None]
                + np.trace(cov[:, 3:, 3:], axis1=1, axis2=2)[None]
            )
            hs, js = np.nonzero(d2 <= cfg.gate * var_bound)
            if hs.size:
                e = np.array([gtsam.Pose3.Logmap(preds[h].between(zs[j])) for h, j in zip(hs, js)])
                S = P_pred[hs] + cov[js]
                maha = np.einsum("ni,ni->n", e, np.linalg.solve(S, e[..., None])[..., 0])
                logdet = np.linalg.slogdet(S)[1]
                # log det(I + P- C^-1) = log det S - log det C
                ll = fit_score(maha, cfg.student_dof) - 0.5 * (logdet - logdet_c[js])
                ll[maha > cfg.gate] = -np.inf
                log_assoc[hs, js] = logw_h[hs] + logw_c[js] + ll
                maha_hj[hs, js] = maha
        log_birth = np.log(cfg.birth_probability) + logw_c
        complete = J >= cfg.full_count
        log_miss = np.log(cfg.miss_probability_full if complete else 1.0 / cfg.full_count)
        if J and not complete:
            log_assoc += np.log(J / cfg.full_count)

        # children: one per candidate (merged over parents + birth), plus one coasting hypothesis
        # per track (its coasting copies merged); every candidate keeps a child (so that a birth
        # can always take over: relocalization), coasting tracks fill the remaining slots
        cols = np.vstack([log_assoc, log_birth[None, :]])  # (H+1, J): parents, then the birth
        children = [
            (float(lw), "child", j, int(p))
            for j, (lw, p) in enumerate(
                zip(np.logaddexp.reduce(cols, axis=0), np.argmax(cols, axis=0))
            )
        ]
        # a coasting track pays the Occam factor of an average consistent association,
        # 1/2 log det(I + P- C_mean^-1), so that a miss is neutral w.r.t. associating
        occam = 0.5 * (logdet_pc - logdet_cm)
        coast: dict[int, tuple[float, int]] = {}  # track id -> (merged log-weight, best hypothesis)
        for h, t in enumerate(self._tracks):
            if t.misses >= cfg.max_misses:
                continue
            lw = float(logw_h[h] + log_miss - occam[h])
            if t.track_id in coast:
                merged, best = coast[t.track_id]
                coast[t.track_id] = (
                    float(np.logaddexp(merged, lw)),
                    best if logw_h[best] >= logw_h[h] else h,
                )
            else:
                coast[t.track_id] = (lw, h)
        children.sort(key=lambda e: -e[0])
        kept = children[: cfg.max_hypotheses]
        coasting = sorted(((lw, "coast", h, h) for lw, h in coast.values()), key=lambda e: -e[0])
        kept += coasting[: cfg.max_hypotheses - len(kept)]

        updates = [
            (idx, parent) for logw, kind, idx, parent in kept if kind == "child" and parent != H
        ]
        posterior = (
            self._window_updates(updates, candidates, cov, odometry, preds) if updates else {}
        )
        new_tracks = []
        for logw, kind, idx, parent in kept:
            if kind == "coast":
                t = self._tracks[idx]
                new_tracks.append(
                    Track(preds[idx], P_pred[idx], logw, t.track_id, -1, t.misses + 1)
                )
            elif parent == H:  # birth
                new_tracks.append(self._birth(zs[idx], cov[idx], idx, logw))
            else:
                mean, P = posterior[idx]
                if cfg.student_scale and np.isfinite(cfg.student_dof):
                    P = P * (cfg.student_dof + maha_hj[parent, idx]) / (cfg.student_dof + 6.0)
                new_tracks.append(Track(mean, P, logw, self._tracks[parent].track_id, idx, 0))
        self._tracks = new_tracks

    def _window_updates(
        self,
        updates: list[tuple[int, int]],
        candidates: CandidateSet,
        cov: np.ndarray,
        odometry: Odometry,
        preds: list[gtsam.Pose3],
    ) -> dict[int, tuple[gtsam.Pose3, np.ndarray]]:
        """Fixed-lag windows of two poses, one per (candidate j, parent h) in `updates`: parent
        marginal prior + odometry between-factor + the mixture component of candidate j (its pose
        as a Gaussian PriorFactorPose3, as `factors.mixture.component_factors`), all in ONE graph
        (disjoint keys pose_key(0, 2i), pose_key(0, 2i + 1) for window i) solved by one
        Gauss-Newton from the predictions; the marginal covariance of each new pose is the Schur
        complement of its window's block of the Hessian at the solution (batched numpy).
        Returns {j: (pose, covariance)}."""
        poses = candidates.poses()
        odo_noise = gtsam.noiseModel.Gaussian.Covariance(odometry.covariance)
        graph, init, order = gtsam.NonlinearFactorGraph(), gtsam.Values(), []
        for i, (j, h) in enumerate(updates):
            parent = self._tracks[h]
            k0, k1 = pose_key(0, 2 * i), pose_key(0, 2 * i + 1)
            graph.add(
                gtsam.PriorFactorPose3(
                    k0, parent.mean, gtsam.noiseModel.Gaussian.Covariance(parent.cov)
                )
            )
            graph.add(gtsam.BetweenFactorPose3(k0, k1, odometry.relative, odo_noise))
            graph.add(
                gtsam.PriorFactorPose3(k1, poses[j], gtsam.noiseModel.Gaussian.Covariance(cov[j]))
            )
            init.insert(k0, parent.mean)
            init.insert(k1, preds[h])
            order += [k0, k1]
        result = gtsam.GaussNewtonOptimizer(graph, init, self._gn).optimize()
        hessian = graph.linearize(result).hessian(gtsam.Ordering(order))[0]
        n = len(updates)
        blocks = hessian.reshape(n, 12, n, 12)[
            np.arange(n), :, np.arange(n), :
        ]  # (n,12,12) diagonal blocks
        P = np.linalg.inv(blocks)[:, 6:, 6:]
        P = 0.5 * (P + np.swapaxes(P, 1, 2))
        return {
            j: (result.atPose3(pose_key(0, 2 * i + 1)), P[i]) for i, (j, _) in enumerate(updates)
        }

    def _normalize(self) -> None:
        if not self._tracks:
            return
        logw = np.array([t.logw for t in self._tracks])
        shift = float(np.logaddexp.reduce(logw))
        for t in self._tracks:
            t.logw -= shift

    def _decide(self, num_candidates: int) -> Decision:
        cfg = self.config
        probs = np.zeros(num_candidates)
        track_prob: dict[int, float] = {}
        for t in self._tracks:
            p = float(np.exp(t.logw))
            if t.candidate >= 0:
                probs[t.candidate] += p
            track_prob[t.track_id] = track_prob.get(t.track_id, 0.0) + p
        # log-odds floored at the uninformed 1/full_count: a relocalization birth's tiny prior is
        # not evidence against it to be made up after its decisive update is held out
        floor = -np.log(cfg.full_count - 1.0) if cfg.full_count > 1 else -np.inf
        logit = {
            i: max(floor, float(np.log(p) - np.log1p(-min(p, 1.0 - 1e-15))))
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
            if held_out >= np.log(cfg.commit_threshold / (1.0 - cfg.commit_threshold)):
                self._committed_id = best_id
        if not self._tracks:
            return Decision(probs, -1, False, None, relocalized)
        if self._committed_id is not None:
            mine = [t for t in self._tracks if t.track_id == self._committed_id]
            best = max(mine, key=lambda t: t.logw)
            committed = next((t.candidate for t in mine if t.candidate >= 0), -1)
            return Decision(probs, committed, True, best.mean, relocalized)
        best = max(self._tracks, key=lambda t: t.logw)
        return Decision(probs, -1, False, best.mean, relocalized)
