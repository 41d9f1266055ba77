"""Issue 17: property-based tests of the graphloc log reader (the manifest parser and every CSV
table of a planar log, `graphloc.datasets.graphloc_log.read_team_run`), bounded so the file runs
in seconds. Whatever a crafted manifest or mutated table rows hold, the reader returns a run in
which every data row is used or counted as a skip, or raises a ValueError / FileNotFoundError
naming the run -- never another exception, and never a foreign file's content."""

from __future__ import annotations

import json

from hypothesis import given, settings
from hypothesis import strategies as st

from graphloc.datasets.graphloc_log import read_team_run
from helpers import EXAMPLES, FAST, JSON_LEAVES, REPLACEMENTS, set_json_leaf
from helpers import json_paths as _json_paths
from helpers import write_planar_log as planar_log

TABLE_FILES = [
    "robot1/odometry.csv",
    "robot2/range_bearing.csv",
    "robot2/groundtruth.csv",
    "robot1/range_bearing.csv",
]
FIELDS = ["1000.5", "wheels", "camera", "landmark:6", "landmark:99", "robot1", "robot2", "1e308"]
FIELDS += ["nan", "-1", "0", "", "x", '"', "#", "9" * 400, "1" * 140_000]
CSV_LINES = st.one_of(
    REPLACEMENTS,
    st.lists(st.sampled_from(FIELDS), min_size=0, max_size=7).map(",".join),
)
PATHS = st.sampled_from(
    ["/etc/passwd", "../mr/Barcodes.dat", "robot1/odometry.csv", "landmarks.csv", "", "a\x00b"]
)


def _data_rows(path) -> int:
    lines = path.read_bytes().splitlines()[1:]
    text = [ln.decode("utf-8", "replace") for ln in lines]
    return sum(1 for t in text if t.strip() and not t.lstrip().startswith("#"))


@settings(FAST, max_examples=EXAMPLES or 30)
@given(data=st.data())
def test_log_rows_are_used_or_counted(tmp_path_factory, data):
    """Replace up to three data lines of the tables: the load fails with an error naming the
    run, or every data row is used (the run's contributions) or counted in its skips."""
    root = planar_log(tmp_path_factory.mktemp("log"))
    for _ in range(data.draw(st.integers(1, 3))):
        path = root / data.draw(st.sampled_from(TABLE_FILES))
        lines = path.read_bytes().split(b"\n")
        i = data.draw(st.integers(1, len(lines) - 2))
        new = data.draw(CSV_LINES)
        lines[i] = new if isinstance(new, bytes) else new.encode()
        path.write_bytes(b"\n".join(lines))
    try:
        run = read_team_run(root)
    except (ValueError, FileNotFoundError) as exc:
        assert str(root) in str(exc), exc
        return
    rows = sum(_data_rows(root / f) for f in TABLE_FILES) + _data_rows(
        root / "robot1/groundtruth.csv"
    )
    rows += _data_rows(root / "robot2/odometry.csv")
    assert sum(run.contributions.values()) + run.skips.total == rows, run.skips.as_dict()
    assert all(str(root) in e for e in run.skips.examples)


@settings(FAST, max_examples=EXAMPLES or 40)
@given(data=st.data())
def test_crafted_manifests_load_or_name_the_manifest(tmp_path_factory, data):
    """Any one to three leaves of the manifest replaced (numbers, strings, lists, objects, paths
    out of the run): a run, or an error naming the manifest (or a file of the run) -- and no
    content of a file outside the run in the message."""
    root = planar_log(tmp_path_factory.mktemp("log"))
    doc = json.loads((root / "manifest.json").read_text())
    paths = sorted(_json_paths(doc), key=str)
    for _ in range(data.draw(st.integers(1, 3))):
        where = data.draw(st.sampled_from(paths))
        value = data.draw(st.one_of(JSON_LEAVES, PATHS))
        set_json_leaf(doc, where, value)
    (root / "manifest.json").write_text(json.dumps(doc))
    try:
        run = read_team_run(root)
    except (ValueError, FileNotFoundError) as exc:
        assert str(root) in str(exc), exc
        assert "root:x:0" not in str(exc)
        return
    assert len(run.robots) >= 1


def table_log(tmp):
    """test_io's log: odometry, range-bearing, markers, candidates, 2D ground truth, bearings
    (its scans table left out: it names a point cloud the log does not ship)."""
    from helpers import make_log

    root = make_log(tmp / "log")
    doc = json.loads((root / "manifest.json").read_text())
    del doc["robots"][0]["tables"]["scans"]
    (root / "manifest.json").write_text(json.dumps(doc))
    return root


EVERY_TABLE = [
    "ground/odometry.csv",
    "ground/range_bearing.csv",
    "ground/markers.csv",
    "ground/candidates.csv",
    "ground/groundtruth.csv",
    "climber/bearing.csv",
    "landmarks.csv",
]
ROW_FIELDS = st.sampled_from(
    ["0.3", "0.6", "ceilcam", "cam", "eye", "wheels", "climber", "ground", "landmark:3", "0"]
    + ["1", "2", "-1", "1e308", "nan", "0.5", "320", "3", "", "x", "1" * 140_000]
)
ROWS = st.one_of(REPLACEMENTS, st.lists(ROW_FIELDS, min_size=0, max_size=13).map(",".join))


@settings(FAST, max_examples=EXAMPLES or 30)
@given(data=st.data())
def test_every_table_kind_returns_or_names_the_file(tmp_path_factory, data):
    """Rows of every table kind (and the landmark table) replaced or appended: a run whose
    skips all name a file of the run, or an error naming the run."""
    root = table_log(tmp_path_factory.mktemp("log"))
    for _ in range(data.draw(st.integers(1, 3))):
        path = root / data.draw(st.sampled_from(EVERY_TABLE))
        lines = path.read_bytes().rstrip(b"\n").split(b"\n")
        i = data.draw(st.integers(1, len(lines)))  # len(lines): a new last row
        new = data.draw(ROWS)
        lines[i : i + 1] = [new if isinstance(new, bytes) else new.encode()]
        path.write_bytes(b"\n".join(lines) + b"\n")
    try:
        run = read_team_run(root)
    except (ValueError, FileNotFoundError) as exc:
        assert str(root) in str(exc), exc
        return
    assert all(str(root) in e for e in run.skips.examples), run.skips.examples
