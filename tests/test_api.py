"""The public API and docs/api.md's quick start, run as written."""

import re
from pathlib import Path

import numpy as np

import graphloc

DOC = Path(__file__).resolve().parents[1] / "docs" / "api.md"


def test_public_names_resolve():
    for name in graphloc.__all__:
        assert getattr(graphloc, name) is not None, name


def test_quick_start_runs_as_written():
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    namespace: dict = {}
    exec(compile(blocks[-1], str(DOC), "exec"), namespace)  # the quick start, unchanged
    errors, added, sets = namespace["errors"], namespace["added"], namespace["sets"]
    assert len(added) > 0.8 * len(sets)
    assert np.median(errors) < 0.03 and max(errors) < 0.15
