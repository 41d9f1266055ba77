"""Parsing apart from the front-ends (issue 49): a log's rows through the registry of table
handlers (`graphloc.datasets.log_rows`), then the front-end stage
(`graphloc.datasets.graphloc_log.run_front_ends`)."""

from __future__ import annotations

import numpy as np

from graphloc.datasets.graphloc_log import read_team_run, run_front_ends, team_run
from graphloc.datasets.log_rows import TABLE_HANDLERS, RowContext, Skip, read_log_rows
from graphloc.datasets.scenarios import generate
from graphloc.records import TABLES, RelativePose2D
from graphloc.run import Motion


def test_every_table_has_one_handler_and_markers_are_read_as_columns():
    assert set(TABLE_HANDLERS) == set(TABLES) - {"markers"}


def test_a_handler_returns_a_row_or_a_skip_naming_its_line():
    parse = TABLE_HANDLERS["relative_pose"].parse
    ctx = RowContext("log/a/rel.csv: line 7", 0, {"a": 0}, (), {})
    good = RelativePose2D(1.0, "a", "wheels", 0.5, 0.1, 0.0, 0.0, 0.01, 0.01, 0.01, line=7)
    bad = RelativePose2D(1.0, "a", "wheels", 1.5, 0.1, 0.0, 0.0, 0.01, 0.01, 0.01, line=7)
    motion = parse(good, ctx)
    assert isinstance(motion, Motion) and (motion.t0, motion.t1) == (0.5, 1.0)
    skip = parse(bad, ctx)
    assert isinstance(skip, Skip) and skip.reason == "bad_relative_pose"
    assert skip.message.startswith("log/a/rel.csv: line 7: ")


def test_parsing_runs_no_front_end_and_the_stage_makes_the_candidate_sets(tmp_path):
    root = tmp_path / "log"
    generate("kaushik-p3p-error", root, seed=3)
    rows = read_log_rows(root)
    assert len(rows.markers["time"]) > 0 and rows.used["markers"] == 0
    front = run_front_ends(rows)
    assert len(front.observations) > 0 and front.used["markers"] > 0 and rows.used["markers"] == 0
    assert all(len(o.candidates) <= 4 for o in front.observations)
    times = [(o.time, o.robot) for o in front.observations]
    assert times == sorted(times)
    run, again = team_run(rows, front), read_team_run(root)
    assert run.contributions == again.contributions
    assert len(run.observations) == len(again.observations)
    for a, b in zip(run.observations, again.observations):
        assert np.array_equal(a.candidates.t, b.candidates.t)
