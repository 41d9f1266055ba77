"""The public API and docs/api.md's quick start, run as written."""

import re
import tomllib
from pathlib import Path

import numpy as np

import graphloc

DOC = Path(__file__).resolve().parents[1] / "docs" / "api.md"


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
