"""The seeds' tables from logs (benchmarks.front_door): a scenario's `graphloc simulate`
log through open_run and the team graph, with the statistics the tables pool."""

import numpy as np

from benchmarks.front_door import feng_table_iii_run, simulated_run, truth_at
from benchmarks.hypotheses import WRONG_DISTANCE
from benchmarks.seed004 import front_door_run
from graphloc.datasets.kaushik import KaushikConfig


def test_feng_run_converges_right_and_its_estimates_follow_the_truth():
    overrides = {"ceiling": "sloped", "curve": "sine", "max_time": 6.0}
    out = feng_table_iii_run(overrides, 5, WRONG_DISTANCE)
    assert out["converged"] is not None and not out["wrong"]
    assert out["correct_lock"] == out["converged"] and out["wrong_locked_frames"] == 0
    assert out["resolved_frames"] == out["frames"] - out["converged"]
    assert out["rmse_locked_batch"] < 0.05 and out["rmse_locked_online"] < 0.05
    run = simulated_run("feng-probabilistic", 5, overrides)
    r = run.index("climber")
    gt_t, gt_p = run.groundtruth[r]
    assert np.allclose(
        truth_at(run, r, gt_t[[1, 3]]), [gt_p[1].translation(), gt_p[3].translation()]
    )


def test_seed004_run_both_columns_from_one_log():
    x = front_door_run((KaushikConfig(runs=1, frames=8, focal_mm=26.0), 4))
    assert len(x["raw"]) == len(x["graphloc"]) == 8 == len(x["candidates"])
    # graphloc (no truth) against the oracle's genuine candidate of each frame
    assert np.sqrt(np.mean(x["graphloc"] ** 2)) < np.sqrt(np.nanmean(x["raw"] ** 2))
