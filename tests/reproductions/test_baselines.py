"""The seeds' baselines behind the engines' per-frame interface: straight-line test (seed 000
Sec. IV), belief vector (seed 000 Sec. V), particle filter (seed 004 Sec. II-C)."""

import gtsam
import numpy as np
import pytest

from benchmarks.baselines.belief_vector import BeliefVector, BeliefVectorConfig, likelihood
from benchmarks.baselines.particle_filter import (
    ParticleFilter,
    ParticleFilterConfig,
    plane_basis,
    sample_motion,
)
from graphloc.datasets.feng_deterministic import Seed000Config, simulate_straight_line_trials
from benchmarks.baselines.straight_line import (
    StraightLineBaseline,
    StraightLineConfig,
    localize_by_straight_line,
)
from graphloc.candidates import CandidateSet
from graphloc.datasets.feng import (
    FengProbabilisticConfig,
    noisy_odometry,
    odometry_covariance,
)
from graphloc.seams import Odometry
from helpers import simulate_feng as simulate


def test_straight_line_baseline_agrees_with_the_batch_test():
    trials = simulate_straight_line_trials(20, seed=1, config=Seed000Config(pixel_sigma=0.0))
    choice = localize_by_straight_line(trials.pixels, trials.K, trials.ground)
    agree = genuine = 0
    for t in range(20):
        engine = StraightLineBaseline(StraightLineConfig(spacing=1, max_error=10.0))
        for s in range(3):
            d = engine.update(
                choice.candidates.candidate_set(3 * t + s, time=float(s)),
                None if s == 0 else Odometry(gtsam.Pose3(), np.eye(6)),
            )
        if choice.found[t]:
            agree += int(d.committed == choice.chosen[t, 2])
            pos = choice.candidates.t_wc[3 * t + 2]
            valid = choice.candidates.valid[3 * t + 2]
            nearest = int(
                np.argmin(
                    np.where(valid, np.linalg.norm(pos - trials.positions[t, 2], axis=1), np.inf)
                )
            )
            genuine += int(d.committed == nearest)
    assert agree == int(choice.found.sum())
    assert genuine >= 0.95 * choice.found.sum()  # noise-free: the genuine combination is on a line


def test_straight_line_baseline_needs_three_frames_and_a_small_error():
    run, odo = simulate(seed=0)
    engine = StraightLineBaseline(StraightLineConfig(spacing=2, max_error=1e-9))
    decisions = [engine.update(c, o) for c, o in zip(run.candidates[:6], odo[:6])]
    assert not any(d.locked for d in decisions)  # a 1e-9 m line error is never reached with noise
    loose = StraightLineBaseline(StraightLineConfig(spacing=2, max_error=10.0))
    decisions = [loose.update(c, o) for c, o in zip(run.candidates[:6], odo[:6])]
    assert [d.locked for d in decisions] == [False] * 4 + [True] * 2  # three snapshots 2 apart


def test_belief_likelihood_definitions():
    a = np.array([[0.02, 0.0, 0.0], [0.02, 0.0, 0.0], [0.02, 0.0, 0.0]])
    om = np.array([[0.02, 0.0, 0.0], [0.0, 0.02, 0.0], [np.inf, np.inf, np.inf]])
    f1 = likelihood(a, om, BeliefVectorConfig(likelihood="inner_product", floor=1e-3))
    np.testing.assert_allclose(f1, [1.0, 1e-3, 0.0])
    f2 = likelihood(a, om, BeliefVectorConfig(likelihood="distance_angle", lam=5.0))
    np.testing.assert_allclose(f2, [1.0, np.exp(-(0.02 * np.sqrt(2) + 5.0 * np.pi / 2)), 0.0])
    with pytest.raises(ValueError, match="likelihood"):
        BeliefVectorConfig(likelihood="cosine")


@pytest.mark.parametrize("definition", ["inner_product", "distance_angle"])
def test_belief_vector_converges_correctly_in_the_seed_noise_regime(definition):
    """With exact P3P (the seed's sub-mm accuracy) the seed's algorithm works as published."""
    for seed in range(3):
        run, odo = simulate(ceiling="level", curve="quadratic", seed=seed, pixel_sigma=0.0)
        engine = BeliefVector(BeliefVectorConfig(likelihood=definition))
        decisions = [engine.update(c, o) for c, o in zip(run.candidates, odo)]
        k = next(i for i, d in enumerate(decisions) if d.locked)
        assert decisions[k].committed == run.candidates[k].meta["genuine"]
        assert np.linalg.norm(decisions[-1].pose.translation() - run.t_wc[-1]) < 0.01


def test_belief_vector_drops_untraced_solutions_and_restarts():
    R = np.repeat(np.eye(3)[None], 2, axis=0)
    step = Odometry(gtsam.Pose3(gtsam.Rot3(), np.array([0.02, 0.0, 0.0])), np.eye(6) * 1e-4)
    engine = BeliefVector()
    engine.update(CandidateSet(R, np.array([[0.0, 0, 0], [1.0, 0, 0]]), np.ones(2), time=0.0))
    # solution 1 jumps 0.5 m (beyond the 0.05 m gate): only solution 0 keeps a track
    d = engine.update(
        CandidateSet(R, np.array([[0.02, 0, 0], [1.5, 0, 0]]), np.ones(2), time=0.1), step
    )
    np.testing.assert_allclose(d.probabilities, [1.0, 0.0])
    assert d.locked and d.committed == 0
    # every track lost: uniform restart over the new solutions, the commit is released
    d = engine.update(
        CandidateSet(R, np.array([[3.0, 0, 0], [4.0, 0, 0]]), np.ones(2), time=0.2), step
    )
    np.testing.assert_allclose(d.probabilities, [0.5, 0.5])
    assert d.relocalized and not d.locked


def test_particle_motion_model_keeps_the_normal_offset():
    rng = np.random.default_rng(0)
    basis = plane_basis((1.0, 0.0, -1.0))
    start = np.zeros((20000, 3))
    step = np.tile(0.1 * basis[0] + 0.05 * basis[1] + 0.3 * basis[2], (20000, 1))
    moved = sample_motion(start, step, basis, 0.01, 0.15, rng)
    np.testing.assert_allclose(moved @ basis[2], 0.0, atol=1e-12)  # Algorithm 1 line 7: z' = z
    np.testing.assert_allclose((moved @ basis[:2].T).mean(axis=0), [0.1, 0.05], atol=2e-3)
    no_noise = sample_motion(start[:1], step[:1], basis, 0.0, 0.0, rng)
    np.testing.assert_allclose(no_noise @ basis[:2].T, [[0.1, 0.05]], atol=1e-12)


def test_particle_filter_weights_merge_additively():
    R = np.repeat(np.eye(3)[None], 2, axis=0)
    step = Odometry(gtsam.Pose3(gtsam.Rot3(), np.array([0.02, 0.0, 0.0])), np.eye(6) * 1e-4)
    pf = ParticleFilter(ParticleFilterConfig(alpha1=0.0, alpha2=0.0, sigma=0.05))
    pf.update(CandidateSet(R, np.array([[0.0, 0, 0], [1.0, 1.0, 0]]), np.ones(2), time=0.0))
    probs = []
    for k in range(1, 6):
        # particle 0's prediction matches a new solution exactly; particle 1's nearest new
        # solution is 0.5 m off its prediction (RBF weight ~ 0)
        c = CandidateSet(
            R,
            np.array([[0.02 * k, 0, 0], [1.0 + 0.02 * k, 1.0 + 0.5 * k, 0]]),
            np.ones(2),
            time=0.1 * k,
        )
        probs.append(pf.update(c, step).probabilities[0])
    # w0 <- (w0 + 1) / (1 + sum w): 0.5 -> 0.75 -> 0.875 ... (Algorithm 2 lines 5-6)
    np.testing.assert_allclose(probs, 1.0 - 0.5 ** np.arange(2, 7), atol=1e-9)
    assert pf.update(
        CandidateSet(R, np.array([[0.12, 0, 0], [1.12, 4.0, 0]]), np.ones(2), time=0.6), step
    ).locked


@pytest.mark.parametrize("engine", [BeliefVector(), ParticleFilter(), StraightLineBaseline()])
def test_engines_share_the_interface_and_reject_bad_input(engine):
    run, odo = simulate(seed=3)
    d = engine.update(run.candidates[0], odo[0])
    assert d.probabilities.shape == (len(run.candidates[0]),)
    d = engine.update(run.candidates[1], odo[1])
    assert d.probabilities.shape == (len(run.candidates[1]),)
    with pytest.raises(ValueError, match="backwards"):
        engine.update(run.candidates[0], odo[1])
    with pytest.raises(ValueError, match="odometry is required"):
        engine.update(run.candidates[2])
    with pytest.raises(ValueError, match="CandidateSet"):
        engine.update(np.zeros((4, 3)), odo[2])


def test_belief_likelihood_readings_of_issue_20():
    """The readings swept by benchmarks.seed_baselines: Def. 1 as (1 + cos) / 2,
    Def. 2's distance as 1 / (1 + d)."""
    a = np.array([[0.02, 0.0, 0.0], [0.02, 0.0, 0.0], [0.02, 0.0, 0.0]])
    om = np.array([[0.02, 0.0, 0.0], [-0.02, 0.0, 0.0], [0.0, 0.02, 0.0]])
    shifted = likelihood(a, om, BeliefVectorConfig(likelihood="inner_product_shifted"))
    np.testing.assert_allclose(shifted, [1.0, 0.0, 0.5], atol=1e-12)
    inverse = likelihood(a, om, BeliefVectorConfig(likelihood="distance_angle_inverse", lam=2.0))
    d = np.array([0.0, 0.04 + 2.0 * np.pi, 0.02 * np.sqrt(2) + 2.0 * np.pi / 2])
    np.testing.assert_allclose(inverse, 1.0 / (1.0 + d))


def test_odometry_noise_readings():
    """Sec. VI-B "15% on all three dimensions": per axis (a zero component stays zero) or
    isotropic (15 % of the step on every axis); unknown models are refused."""
    n = 4000
    trel = np.tile([0.02, 0.0, 0.0], (n, 1))
    Rrel = np.repeat(np.eye(3)[None], n, axis=0)
    per_axis = np.array(
        [p.translation() for p in noisy_odometry(Rrel, trel, 0.15, 0.0, np.random.default_rng(0))]
    )
    assert np.all(per_axis[:, 1:] == 0.0)
    np.testing.assert_allclose(per_axis[:, 0].std(), 0.15 * 0.02, rtol=0.05)
    iso = np.array(
        [
            p.translation()
            for p in noisy_odometry(
                Rrel, trel, 0.15, 0.0, np.random.default_rng(0), model="isotropic"
            )
        ]
    )
    np.testing.assert_allclose(iso.std(axis=0), [0.003] * 3, rtol=0.05)
    cov = odometry_covariance(gtsam.Pose3(gtsam.Rot3(), [0.02, 0, 0]), 0.15, model="isotropic")
    np.testing.assert_allclose(np.sqrt(np.diag(cov)[3:]), [0.003 + 1e-3] * 3)
    with pytest.raises(ValueError, match="model"):
        noisy_odometry(Rrel[:1], trel[:1], 0.15, 0.0, np.random.default_rng(0), model="polar")
    with pytest.raises(ValueError, match="odometry_model"):
        FengProbabilisticConfig(odometry_model="polar")


def test_straight_line_orientation_readings():
    """Seed000Config.orientation: "kept" holds C's rotation over the three snapshots (the
    default; unchanged random stream), "redrawn" draws it anew for snapshots 2 and 3."""
    kept = simulate_straight_line_trials(30, seed=2, config=Seed000Config())
    assert np.array_equal(kept.R_snapshots, np.repeat(kept.R_wc[:, None], 3, axis=1))
    redrawn = simulate_straight_line_trials(30, seed=2, config=Seed000Config(orientation="redrawn"))
    np.testing.assert_array_equal(redrawn.R_snapshots[:, 0], redrawn.R_wc)
    assert np.abs(redrawn.R_snapshots[:, 1] - redrawn.R_wc).max() > 0.05
    # noise-free, the straight-line test still picks the genuine combination of the new images
    clean = simulate_straight_line_trials(
        30, seed=2, config=Seed000Config(orientation="redrawn", pixel_sigma=0.0)
    )
    choice = localize_by_straight_line(clean.pixels, clean.K, clean.ground)
    err = np.linalg.norm(choice.chosen_positions() - clean.positions, axis=2)
    assert (err.max(axis=1) < 1e-6).mean() >= 0.9
    with pytest.raises(ValueError, match="orientation"):
        Seed000Config(orientation="spinning")


def test_belief_action_frame_readings():
    """a_t rotated by each solution's rotation ("solution", the default) separates two
    solutions that moved alike but face differently; one world-frame reading ("world") cannot."""
    R = np.stack([np.eye(3), gtsam.Rot3.Rz(np.pi / 2).matrix()])
    step = Odometry(gtsam.Pose3(gtsam.Rot3(), np.array([0.02, 0.0, 0.0])), np.eye(6) * 1e-4)
    first = CandidateSet(R, np.array([[0.0, 0, 0], [1.0, 0, 0]]), np.ones(2), time=0.0)
    moved = CandidateSet(R, np.array([[0.02, 0, 0], [1.02, 0, 0]]), np.ones(2), time=0.1)
    probs = {}
    for frame in ("solution", "world"):
        engine = BeliefVector(BeliefVectorConfig(action_frame=frame))
        engine.update(first)
        probs[frame] = engine.update(moved, step).probabilities
    assert probs["solution"][0] > 0.99
    np.testing.assert_allclose(probs["world"], [0.5, 0.5])
    with pytest.raises(ValueError, match="action_frame"):
        BeliefVectorConfig(action_frame="camera")
