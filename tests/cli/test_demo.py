"""The README's main job: `graphloc demo` fuses the ground and ceiling maps of the default
dual-robot-room scenario end to end and writes the report, the fused map and the pictures."""

import json

from graphloc.cli import main


def test_demo_runs_the_whole_fusion_pipeline(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "fusion_report.json").read_text())
    err = report["errors_vs_truth"]
    # seed 004 reports 1-2 deg; the bar is <= 0.1 deg and <= 1 cm (median over placements)
    assert err["rot_deg"] < 0.1 and err["trans_m"] < 0.01, err
    for name in (
        "fused_map.ply",
        "fused_map.pcd",
        "fused_top.png",
        "fused_side.png",
        "trajectory_ground.tum",
        "trajectory_ceiling.tum",
    ):
        assert (tmp_path / name).stat().st_size > 0, name
    assert "error vs truth" in capsys.readouterr().out
