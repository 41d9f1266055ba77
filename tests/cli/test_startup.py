"""The command line starts light (issue 47): building graphloc's parser -- every verb's options,
derived from their config dataclasses -- and `graphloc VERB --help` / `--version` import none of
the heavy libraries; each loads where it is used. Checked on `sys.modules` of a fresh
interpreter, which is deterministic; the wall times are measured by scripts/bench_startup.py
(docs/results_startup.md), never here."""

import json
import subprocess
import sys

from graphloc.cli import VERBS

# libraries that cost tenths of a second to seconds to import (NumPy ~0.1 s, Open3D ~0.8 s)
HEAVY = (
    "numpy",
    "scipy",
    "gtsam",
    "open3d",
    "cv2",
    "matplotlib",
    "kiss_icp",
    "evo",
    "rosbags",
    "pandas",
    "pyarrow",
    "rerun",
    "ray",
    "pydantic",  # loads on a config's first construction (graphloc.config), not for --help
)


def _loaded(code: str) -> dict:
    """Run `code` in a fresh interpreter; its last stdout line is JSON."""
    probe = f"""
import contextlib, io, json, sys
{code}
heavy = sorted(m for m in {HEAVY!r} if m in sys.modules)
print(json.dumps({{"heavy": heavy, "modules": sorted(sys.modules)}}))
"""
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_building_the_parser_imports_no_heavy_library():
    loaded = _loaded("import graphloc.cli\ngraphloc.cli.build_parser()")
    assert loaded["heavy"] == []
    for module in VERBS.values():  # every verb's options were built
        assert f"graphloc.commands.{module}" in loaded["modules"]


def test_every_verb_help_imports_no_heavy_library():
    code = f"""
from graphloc.cli import main
for verb in {list(VERBS)!r}:
    with contextlib.redirect_stdout(io.StringIO()) as text:
        try:
            main([verb, "--help"])
        except SystemExit as exc:
            assert exc.code == 0, (verb, exc.code)
    assert "usage: graphloc " + verb in text.getvalue(), verb
"""
    assert _loaded(code)["heavy"] == []


def test_version_loads_no_verb():
    code = """
from graphloc.cli import main
with contextlib.redirect_stdout(io.StringIO()) as text:
    try:
        main(["--version"])
    except SystemExit as exc:
        assert exc.code == 0
assert text.getvalue().startswith("graphloc ")
"""
    loaded = _loaded(code)
    assert loaded["heavy"] == []
    assert not [
        m
        for m in loaded["modules"]
        if m.startswith("graphloc.commands.") and m not in ("graphloc.commands.common",)
    ]


def test_a_verb_loads_only_its_own_module():
    """`graphloc smooth ...` parses with smooth's options alone (`cli.verbs_to_load`)."""
    code = """
from graphloc.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    try:
        main(["validate", "--help"])
    except SystemExit:
        pass
"""
    loaded = _loaded(code)["modules"]
    assert "graphloc.commands.validate" in loaded
    assert "graphloc.commands.fuse_maps" not in loaded and "graphloc.commands.demo" not in loaded
