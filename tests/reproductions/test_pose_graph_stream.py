"""benchmarks.pose_graph_stream: PoseGraphHypotheses behind the HypothesisTracker's interface
(issue 51's side-by-side, scripts/bench_candidate_engines.py), on the first frames of seed 000
Table III's first level- and sloped-ceiling line runs (benchmarks.hypotheses.trial's seeds 0
and 1000)."""

import gtsam
import numpy as np
import pytest

from benchmarks.hypotheses import odometry_steps
from benchmarks.pose_graph_stream import PoseGraphStream
from graphloc.datasets.feng import FengProbabilisticConfig, FengProbabilisticScenario
from graphloc.hypotheses.pose_graph import PoseGraphConfig

FRAMES = 20


def _simulate(ceiling: str, seed: int):
    sim = FengProbabilisticConfig(ceiling=ceiling, curve="line", seed=seed)
    simulated = FengProbabilisticScenario.simulate(sim)
    return simulated, odometry_steps(simulated, sim)


@pytest.fixture(scope="module")
def run():
    return _simulate("level", 0)


def _feed(stream, run):
    simulated, odometry = run
    frames = zip(simulated.candidates[:FRAMES], odometry[:FRAMES])
    return [stream.update(candidates, odo) for candidates, odo in frames]


@pytest.mark.parametrize(
    "config, null",
    [
        (PoseGraphConfig(window=1), "partial"),
        # a null on every set (the null no longer crowds out the candidates), heavy tails
        (PoseGraphConfig(window=1, candidate_dof=6.0, margin=6.0), "all"),
    ],
    ids=["gaussian-partial", "student-all"],
)
def test_it_locks_the_genuine_candidate_and_its_decisions_have_the_trackers_shapes(
    run, config, null
):
    simulated, _ = run
    decisions = _feed(PoseGraphStream(config, null=null), run)
    for k, d in enumerate(decisions):
        candidates = simulated.candidates[k]
        assert d.probabilities.shape == (len(candidates),)
        assert d.probabilities.min() >= 0.0 and d.probabilities.sum() <= 1.0 + 1e-9
        assert -1 <= d.committed < len(candidates) and isinstance(d.locked, bool)
        assert isinstance(d.pose, gtsam.Pose3) and d.relocalized is False
        if d.committed >= 0:
            assert d.locked and d.probabilities[d.committed] == 1.0
    locked = [k for k, d in enumerate(decisions) if d.locked]
    assert locked and locked[0] <= 10
    for k in locked:  # every locked frame on the genuine candidate, its pose near the truth
        d = decisions[k]
        assert d.committed in (-1, simulated.candidates[k].meta["genuine"])
        assert np.linalg.norm(d.pose.translation() - simulated.t_wc[k]) < 0.1


def test_a_set_every_frame_is_judged_on_the_engines_own_schedule():
    """The engine judges `window` steps after the first branching since its last judgement: a
    candidate set branches every frame, and on the sloped ceiling (the pseudo solutions follow
    the odometry, several branches survive) the default window still judges and decides (its
    judgements once counted from the last branching, which a stream that branches every frame
    never got `window` steps past)."""
    sloped = _simulate("sloped", 1000)
    stream = PoseGraphStream(PoseGraphConfig())
    decisions = _feed(stream, sloped)
    stats = stream.engine.stats
    assert stats["branchings"] == FRAMES - 1
    assert stats["judgements"] >= (FRAMES - 1) // PoseGraphConfig().window
    assert any(d.locked for d in decisions)


def test_bad_options_are_refused():
    with pytest.raises(ValueError, match="null"):
        PoseGraphStream(null="some")


def test_the_benchmark_refuses_an_unknown_method(capsys):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "scripts" / "bench_candidate_engines.py"
    spec = importlib.util.spec_from_file_location("bench_candidate_engines", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    with pytest.raises(SystemExit) as exit_info:
        script.main(["--methods", "pose_graph_nope", "--out", "unused"])
    assert exit_info.value.code == 2
    assert "pose_graph_nope" in capsys.readouterr().err
