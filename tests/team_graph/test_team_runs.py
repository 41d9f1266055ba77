"""The front-door benchmark's seed 004 comparator (`team_runs.today_seed004_smoothing`): the
smoothing issue 14 names as today's, run on a `graphloc simulate kaushik-p3p-error` log."""

import numpy as np
import pytest

from graphloc.datasets.scenarios import generate
from benchmarks.team_runs import today_seed004_smoothing


def _log(tmp_path, **overrides):
    run_dir = tmp_path / "run"
    generate("kaushik-p3p-error", run_dir, 3, {"frames": 5, **overrides})
    return run_dir


def test_today_smoothing_recovers_a_nearly_noise_free_track(tmp_path):
    """Pixels at 1e-3 px and odometry at 1e-4 on a track whose genuine P3P candidates are all
    within 6 mm of the truth (seed 3's first five frames; its sixth is past the P3P fold, where
    no candidate is near the truth): the smoothed track is within a centimetre."""
    run_dir = _log(tmp_path, noise_variance=1e-6, odometry_noise=1e-4, odometry_rot_sigma=1e-5)
    out = today_seed004_smoothing(run_dir)
    assert out["frames"] == 5
    assert np.sqrt(out["batch_sq"] / out["frames"]) < 0.01


def test_today_smoothing_error_grows_with_pixel_noise(tmp_path):
    quiet = today_seed004_smoothing(_log(tmp_path / "a", noise_variance=1e-6))
    noisy = today_seed004_smoothing(_log(tmp_path / "b", noise_variance=10.0))
    assert noisy["batch_sq"] > 100 * quiet["batch_sq"]


def test_today_smoothing_refuses_a_log_whose_frames_do_not_chain(tmp_path):
    run_dir = _log(tmp_path)
    table = next(p for p in (run_dir / "climber").iterdir() if "relative_pose" in p.name)
    lines = table.read_text().splitlines()
    table.write_text("\n".join(lines[:-3] + lines[-2:]) + "\n")  # one step missing
    with pytest.raises(ValueError, match="do not chain"):
        today_seed004_smoothing(run_dir)


def test_report_pools_runs_and_renders_the_doc_from_its_json(tmp_path):
    """benchmarks.team_runs_report.write: per-cell RMSE pooled over the runs' frames
    (sqrt(sum sq / sum frames)), the doc rendered from the JSON written beside it."""
    import json

    from benchmarks.render import render
    from benchmarks.team_runs import FENG_CELLS, KAUSHIK_CELLS
    from benchmarks.team_runs_report import write

    def front_door(sq: float, frames: int) -> dict:
        keys = ("batch_sq_after_commit", "online_sq_after_commit", "causal_sq_after_commit",
                "batch_sq_all", "online_sq_all", "batch_offset_sq",
                "batch_predicted_sq")  # fmt: skip
        return {k: sq for k in keys} | {
            "frames_after_commit": frames, "frames": frames, "committed": 2, "wrong": 0,
            "merged": 1, "placed": True, "candidate_sets": 3, "consistent_batch": True,
            "consistent_online": True, "warnings_batch": False, "warnings_online": True,
        }  # fmt: skip

    today = {"batch_sq": 1.0, "online_sq": 1.0, "frames": 4, "wrong": 1}
    # two runs per cell: 0.04 m^2 over 1 frame and 0.12 m^2 over 3 frames pool to 0.2 m RMS
    runs = [front_door(0.04, 1), front_door(0.12, 3)]
    rows = [{"scenario": "feng-probabilistic", "ceiling": c, "curve": k, "front_door": fd,
             "today": today} for c, k in FENG_CELLS for fd in runs]  # fmt: skip
    rows += [{"scenario": "kaushik-p3p-error", "focal_mm": f, "noise_variance": v,
              "front_door": fd, "oracle": fd, "today": today}
             for f, v in KAUSHIK_CELLS for fd in runs]  # fmt: skip
    rows += [{"scenario": s, "front_door": fd} for s in ("breitenmoser-target",
             "feng-deterministic") for fd in runs]  # fmt: skip
    doc = tmp_path / "results_team.md"
    summary = write(rows, tmp_path / "out", doc, "scripts/bench_team_runs.py --size quick")
    cell = summary["feng-probabilistic"]["level/line"]
    assert cell["batch_rmse"] == pytest.approx(0.2) and cell["today_batch_rmse"] == 0.5
    assert summary["breitenmoser-target"]["consistent_batch"] == 2
    rendered = json.loads(doc.with_suffix(".json").read_text())
    assert rendered["command"] == "scripts/bench_team_runs.py --size quick"
    text = doc.read_text()
    assert text == render("team_runs", rendered)
    cells = [
        c.strip() for c in next(x for x in text.splitlines() if "| level/line" in x).split("|")
    ]
    assert cells[1:5] == ["level/line", "2 (2)", "0 / 2 / 4", "0.2000"]
    assert cells[-2] == "2 / 2 (0 / 2)"
    assert (
        "Target (front door batch at or below today's experiment code in every cell): met." in text
    )
    saved = json.loads((tmp_path / "out" / "team_runs.json").read_text())
    assert len(saved["runs"]) == len(rows) and (tmp_path / "out" / "team_runs_feng.png").is_file()
