"""Package discovery for setuptools (everything else is in pyproject.toml).

The packages are found, not listed: every folder with an `__init__.py` under a source folder of
`[tool.setuptools] package-dir` in pyproject.toml, named under that folder's package. factors/
and datasets/ are the source folders of graphloc.factors and graphloc.datasets, which
pyproject's `[tool.setuptools.packages.find]` cannot express (it names a package after its
folder, so it would find a top-level `factors` and `datasets`, and the PyPI `datasets` package
collides); tests/cli/test_packaging.py checks that the wheel holds every module of the source
folders and nothing at the top level but graphloc."""

import tomllib
from pathlib import Path

from setuptools import find_packages, setup

ROOT = Path(__file__).resolve().parent
PACKAGE_DIR = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"][
    "setuptools"
]["package-dir"]


def packages() -> list[str]:
    """Each mapped package and the packages found in its folder, under its name."""
    found = []
    for name, folder in PACKAGE_DIR.items():
        found += [name] + [f"{name}.{sub}" for sub in find_packages(str(ROOT / folder))]
    return found


setup(packages=packages())
