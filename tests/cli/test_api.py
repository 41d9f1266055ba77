"""The public API and docs/api.md's quick start, run as written."""

import re
import tomllib
from pathlib import Path

import numpy as np

import graphloc

DOC = Path(__file__).resolve().parents[2] / "docs" / "api.md"


def test_public_names_resolve():
    """Each public name is graphloc's own class or function (loaded on first use), and
    __version__ is the distribution's version."""
    project = tomllib.loads((DOC.parents[1] / "pyproject.toml").read_text())["project"]
    assert graphloc.__version__ == project["version"]
    for name in set(graphloc.__all__) - {"__version__"}:
        obj = getattr(graphloc, name)
        assert callable(obj) and obj.__module__.startswith("graphloc."), (name, obj)


def test_quick_start_runs_as_written():
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    namespace: dict = {}
    exec(compile(blocks[-1], str(DOC), "exec"), namespace)  # the quick start, unchanged
    errors, added, sets = namespace["errors"], namespace["added"], namespace["sets"]
    assert len(added) > 0.8 * len(sets)
    assert np.median(errors) < 0.03 and max(errors) < 0.15


def test_run_team_is_what_smooth_writes(tmp_path, cli):
    """docs/api.md's `run_team` block, on a simulated run, writes what `graphloc smooth` writes
    (the same metrics, timings aside): one route for the command line and the API."""
    import json

    from graphloc.cli import main

    run = tmp_path / "out" / "feng_run"
    assert main(["simulate", "feng-probabilistic", "--out", str(run), "--seed", "3", "-q"]) == 0
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    block = next(b for b in blocks if "run_team" in b)
    cwd = Path.cwd()
    try:
        import os

        os.chdir(tmp_path)
        namespace: dict = {}
        exec(compile(block, str(DOC), "exec"), namespace)
    finally:
        os.chdir(cwd)
    outcome = namespace["outcome"]
    assert outcome.metrics["consistent"] is True
    got = cli(
        ["smooth", str(run), "--out", str(tmp_path / "cli"), "--no-progress"], out=tmp_path / "cli"
    )
    assert got.code == 0, got.err[-2000:]
    api = json.loads((tmp_path / "out" / "feng_smoothed" / "metrics.json").read_text())
    verb = json.loads((tmp_path / "cli" / "metrics.json").read_text())
    for key in ("per_robot", "decisions", "consistency", "counts", "options", "landmark_map"):
        assert api[key] == verb[key], key
