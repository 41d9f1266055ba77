"""The consistency verdict of every solve (`team_graph.verdict`, docs/outputs.md
"Consistency"): a clean run passes; a run whose measurements no solution explains says so, in
metrics.json, on the terminal and, with --strict, in its exit code."""

import csv
import json

import numpy as np
import pytest

from graphloc.cli import main
from graphloc.exitcodes import INCONSISTENT, OK
from graphloc.pipelines.team_graph.verdict import ConsistencyTest, judge


@pytest.fixture(scope="module")
def feng_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("feng")
    assert main(["simulate", "feng-probabilistic", "--seed", "7", "--out", str(root / "run")]) == 0
    return root / "run"


def _swap_uv(run, out):
    """The run with u and v swapped in every markers table (the before-stop hook's check)."""
    import shutil

    shutil.copytree(run, out)
    for f in out.rglob("markers.csv"):
        rows = list(csv.reader(f.open()))
        iu, iv = rows[0].index("u"), rows[0].index("v")
        for r in rows[1:]:
            r[iu], r[iv] = r[iv], r[iu]
        csv.writer(f.open("w", newline="")).writerows(rows)
    return out


@pytest.mark.parametrize("verb", ["smooth", "online"])
def test_a_clean_run_is_consistent_and_a_swapped_one_is_not(feng_run, tmp_path, capsys, verb):
    out = tmp_path / "clean"
    assert main([verb, str(feng_run), "--out", str(out), "--no-progress", "--strict"]) == OK
    m = json.loads((out / "metrics.json").read_text())
    assert m["consistent"] is True and not m["consistency"]["warnings"]
    assert m["factors"]["marker"]["normalized_chi2"] < 2
    stream = m["candidate_streams"]["climber->ground"]
    assert stream["decided"] > 0 and stream["sets"] == m["decisions"]["candidate_sets"]
    capsys.readouterr()

    bad = _swap_uv(feng_run, tmp_path / "swapped")
    out = tmp_path / "bad"
    code = main([verb, str(bad), "--out", str(out), "--no-progress", "--strict"])
    m = json.loads((out / "metrics.json").read_text())
    err = capsys.readouterr().err
    assert code == INCONSISTENT and m["consistent"] is False
    assert "inconsistent: marker factors" in err and "warning: candidate sets climber" in err
    # every output is written all the same
    assert (out / f"climber_{'batch' if verb == 'smooth' else 'online'}.tum").is_file()


def test_the_test_names_each_failure():
    stats = {
        "landmark": {
            "count": 10,
            "normalized_chi2": 9.0,
            "rms": 3.0,
            "robust": 10,
            "downweighted": 5,
            "downweighted_share": 0.5,
        },
        "odometry": {
            "count": 5,
            "normalized_chi2": 0.5,
            "rms": 0.7,
            "robust": 0,
            "downweighted": 0,
            "downweighted_share": 0.0,
        },
    }
    streams = {"a->b": {"sets": 10, "decided": 0, "undecided": 5, "inconsistent": 5}}
    skips = {"counts": {"unknown_target": 3}, "first": {"unknown_target": "x.csv: line 4"}}
    v = judge(stats, streams, ["c"], skips)
    assert not v["consistent"] and len(v["failures"]) == 3
    assert any("landmark factors: normalized chi-square 9" in f for f in v["failures"])
    assert any("a->b: 5 of 10 inconsistent" in f for f in v["failures"])
    assert any("robot c: left unplaced" in w for w in v["warnings"])
    assert any("3 rows skipped (unknown_target), e.g. x.csv: line 4" in w for w in v["warnings"])
    assert any("none of 10 decided" in w for w in v["warnings"])
    loose = ConsistencyTest(
        max_normalized_chi2=10, max_downweighted_share=0.6, max_inconsistent_share=0.6
    )
    assert judge(stats, streams, [], {}, loose)["consistent"]
    with pytest.raises(ValueError, match="max_downweighted_share"):
        ConsistencyTest(max_downweighted_share=1.5)
    assert np.isfinite(loose.max_normalized_chi2)
