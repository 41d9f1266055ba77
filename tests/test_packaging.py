"""The distribution installs graphloc.factors / graphloc.datasets from factors/ and datasets/,
and never a top-level `factors` or `datasets` module (the PyPI `datasets` package collides)."""

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(ROOT)],
        check=True,
    )
    (whl,) = out.glob("graphloc-*.whl")
    return whl


def test_wheel_has_only_graphloc_top_level(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names}
    assert tops == {"graphloc", next(t for t in tops if t.endswith(".dist-info"))}, tops
    assert "graphloc/factors/__init__.py" in names
    assert "graphloc/datasets/__init__.py" in names
    assert not any(n.startswith(("factors/", "datasets/")) for n in names)


def test_installed_subpackages_resolve_to_source_folders():
    import graphloc.datasets
    import graphloc.factors

    assert Path(graphloc.factors.__file__).parent.name == "factors"
    assert Path(graphloc.datasets.__file__).parent.name == "datasets"


def test_cli_help_lists_only_registered_verbs():
    from graphloc.cli import VERBS

    res = subprocess.run(
        [sys.executable, "-m", "graphloc", "--help"], capture_output=True, text=True, check=True
    )
    for verb in VERBS:
        assert verb in res.stdout
    bad = subprocess.run(
        [sys.executable, "-m", "graphloc", "no-such-verb"], capture_output=True, text=True
    )
    assert bad.returncode != 0 and "invalid choice" in bad.stderr
