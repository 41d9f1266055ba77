"""Ground truth in the outputs of `graphloc smooth` / `online` (issue 47): written at the
estimate's rate by default -- the samples matched to the robot's pose times, with their own
stamps and poses -- or every sample (`--groundtruth-rate full`); the metrics unchanged by it and
equal to evo's on the whole ground truth (`graphloc.eval.associate` is evo's association); a
progress bar while the outputs are written, none with --no-progress / -q."""

import json

import numpy as np
import pytest
from evo.core import sync
from evo.core.trajectory import PoseTrajectory3D
from helpers import write_synthetic_mrclam

from graphloc.cli import main
from graphloc.datasets import open_run
from graphloc.eval import associate, matching_time_indices, read_tum, trajectory_metrics
from graphloc.pipelines.groundtruth import alignment, groundtruth_rows, trajectory
from graphloc.pipelines.report import evaluate
from graphloc.pipelines.team_graph import GraphConfig, solve
from graphloc.runner.team_run import team_graph


@pytest.fixture(scope="module")
def mrclam(tmp_path_factory):
    """A synthetic MRCLAM run: ground truth at 50 Hz, the estimate on a 0.25 s grid."""
    root = tmp_path_factory.mktemp("gt") / "MRCLAM_Synthetic"
    write_synthetic_mrclam(root, duration=20.0)
    return root


def _traj(times):
    t = np.asarray(times, dtype=float)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1))
    return PoseTrajectory3D(
        positions_xyz=np.zeros((len(t), 3)), orientations_quat_wxyz=q, timestamps=t
    )


@pytest.mark.parametrize("n_ref, n_est", [(500, 60), (40, 300), (100, 100)])
def test_associate_makes_evos_pairs(n_ref, n_est):
    """The same pairs as evo's associate_trajectories, whichever trajectory is the longer (evo
    matches from the shorter one)."""
    rng = np.random.default_rng(n_ref + n_est)
    ref = np.sort(rng.uniform(0, 10, n_ref))
    est = np.sort(rng.uniform(0, 10, n_est))
    i_ref, i_est = associate(ref, est, 0.02)
    a, b = sync.associate_trajectories(_traj(ref), _traj(est), max_diff=0.02)
    np.testing.assert_array_equal(ref[i_ref], a.timestamps)
    np.testing.assert_array_equal(est[i_est], b.timestamps)


@pytest.mark.parametrize("seed", range(6))
def test_matching_time_indices_is_evos(seed):
    """graphloc's all-at-once matching returns evo's pairs: random stamps, stamps on a grid with
    exact ties (the earlier one wins), stamps beyond either end, repeated stamps, and an
    unsorted second list (evo's own linear search)."""
    rng = np.random.default_rng(seed)
    grid = np.round(np.arange(0.0, 5.0, 0.1), 6)
    cases = [
        (np.sort(rng.uniform(-1, 11, 80)), np.sort(rng.uniform(0, 10, 200)), 0.03),
        (np.sort(rng.uniform(0, 10, 300)), np.sort(rng.uniform(0, 10, 40)), 0.2),
        (grid + 0.05, grid, 0.05),  # every stamp halfway: a tie each
        (np.repeat(grid, 2), np.repeat(grid[::3], 3), 0.1),
        (np.array([-0.2, 5.02, 7.0]), grid, 0.05),
        (rng.uniform(0, 5, 30), rng.uniform(0, 5, 50), 0.05),  # unsorted
        (np.zeros(0), grid, 0.1),
    ]
    for s1, s2, max_diff in cases:
        mine = matching_time_indices(s1, s2, max_diff)
        evo = sync.matching_time_indices(s1, s2, max_diff)
        np.testing.assert_array_equal(mine[0], np.asarray(evo[0], dtype=int))
        np.testing.assert_array_equal(mine[1], np.asarray(evo[1], dtype=int))


def test_metrics_equal_evo_on_the_whole_ground_truth(mrclam):
    """`evaluate` converts only the ground-truth samples it compares; its numbers are those of
    evo on every sample (the computation before issue 47), bit for bit."""
    run = open_run(mrclam, duration=10.0)
    result = solve(team_graph(run, GraphConfig()), "batch")
    metrics = evaluate(result, run)
    for r, robot in enumerate(run.robots):
        reference = trajectory(*groundtruth_rows(run, r))
        for label, rows in (
            ("batch", result.estimate[r]),
            ("dead_reckoning", result.dead_reckoning[r]),
        ):
            whole = trajectory_metrics(
                reference, trajectory(result.node_times[r], rows), align=alignment(run, r)
            ).as_dict()
            assert metrics["per_robot"][robot.name][label] == whole, (robot.name, label)


def test_groundtruth_file_at_the_estimates_rate_or_full(mrclam, tmp_path):
    outs = {}
    for rate in ("estimate", "full"):
        out = outs[rate] = tmp_path / rate
        args = ["smooth", str(mrclam), "--out", str(out), "--duration", "10", "--no-progress"]
        assert main([*args, "--groundtruth-rate", rate]) == 0
    run = open_run(mrclam, duration=10.0)
    for r, robot in enumerate(run.robots):
        times, rows = groundtruth_rows(run, r)
        est = read_tum(outs["estimate"] / f"{robot.name}_batch.tum")
        at_rate = read_tum(outs["estimate"] / f"{robot.name}_groundtruth.tum")
        full = read_tum(outs["full"] / f"{robot.name}_groundtruth.tum")
        assert full.num_poses == len(times)  # every sample
        # one sample per pose time, each within the metrics' 0.02 s, the samples' own stamps
        assert at_rate.num_poses <= est.num_poses < full.num_poses / 5
        gap = np.abs(at_rate.timestamps[:, None] - est.timestamps[None, :]).min(axis=1)
        assert gap.max() <= 0.02
        kept = np.searchsorted(times, at_rate.timestamps)
        np.testing.assert_array_equal(times[kept], at_rate.timestamps)
        np.testing.assert_allclose(at_rate.positions_xyz, rows[kept, :3], rtol=0, atol=1e-12)
    a, b = (json.loads((outs[k] / "metrics.json").read_text()) for k in ("estimate", "full"))
    assert a["per_robot"] == b["per_robot"]
    assert a["options"]["groundtruth_rate"] == "estimate"
    assert b["options"]["groundtruth_rate"] == "full"
    bad = main(["smooth", str(mrclam), "--out", str(tmp_path / "x"), "--groundtruth-rate", "x"])
    assert bad == 2


def test_progress_while_writing_outputs(mrclam, tmp_path, capsys):
    args = ["smooth", str(mrclam), "--duration", "10"]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    assert "writing outputs" in capsys.readouterr().err
    for quiet in ("--no-progress", "-q"):
        assert main([*args, "--out", str(tmp_path / quiet), quiet]) == 0
        assert "writing outputs" not in capsys.readouterr().err
