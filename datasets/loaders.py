"""One loader protocol, one factory (KISS-ICP's `datasets/` style): every source of runs is a
class with `matches(path)` and `load(path, duration, noise) -> graphloc.run.TeamRun`, and
`open_run(path)` takes the first loader that recognises the path. Pipelines only ever see the
TeamRun, never a specific source."""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from graphloc.datasets.mrclam import MRCLAM, is_mrclam_dir
from graphloc.datasets.rosbag import RosBag
from graphloc.datasets.scan_directory import ScanDirectory
from graphloc.manifest import MANIFEST
from graphloc.datasets.graphloc_log import read_team_run
from graphloc.run import TeamRun, team_run_from_planar, truncate


class RunLoader(Protocol):
    name: str
    expects: str  # what a directory needs for this loader, for the error message
    options: tuple[str, ...]  # the source options (RunOptions.source) `load` takes as keywords

    def matches(self, path: Path) -> bool: ...

    def load(self, path: Path, duration: float | None, noise: dict | None, **source) -> TeamRun: ...


class GraphlocLog:
    """A graphloc log directory (docs/log_format.md, versions 1 and 2)."""

    name = "graphloc-log"
    expects = MANIFEST
    options = ()

    def matches(self, path: Path) -> bool:
        return (path / MANIFEST).is_file()

    def load(self, path: Path, duration: float | None, noise: dict | None) -> TeamRun:
        run = read_team_run(path, overrides=noise)
        return run if duration is None else truncate(run, duration)


class MRCLAMDirectory:
    """A UTIAS MRCLAM dataset directory (Leung et al., IJRR 2011)."""

    name = "mrclam"
    expects = "Barcodes.dat and RobotN_Odometry.dat"
    options = ()

    def matches(self, path: Path) -> bool:
        return is_mrclam_dir(path)

    def load(self, path: Path, duration: float | None, noise: dict | None) -> TeamRun:
        return team_run_from_planar(MRCLAM(path, duration=duration).load(), noise)


# a scan directory last: a log or MRCLAM directory may hold scan files too
LOADERS: tuple[RunLoader, ...] = (GraphlocLog(), MRCLAMDirectory(), RosBag(), ScanDirectory())


def open_run(
    path, duration: float | None = None, noise: dict | None = None, source: dict | None = None
) -> TeamRun:
    """The run at `path` through the first loader that recognises it, optionally cut to the
    first `duration` seconds; `noise` (bearing_sigma, range_sigma, range_sigma_per_m,
    pixel_sigma) replaces what the source states (a config file or CLI flags); `source`: options
    of one kind of source (`RunOptions.source`: a bag's `topics` file, a scan directory's
    `scan_rate`), an error when the source at `path` takes none of them."""
    path = Path(path)
    source = dict(source or {})
    for loader in LOADERS:
        if loader.matches(path):
            extra = sorted(set(source) - set(loader.options))
            if extra:
                flags = ", ".join("--" + k.replace("_", "-") for k in extra)
                raise ValueError(f"{path}: {flags} does not apply to a {loader.name} source")
            return loader.load(path, duration, noise, **source)
    known = "; ".join(f"{loader.name} ({loader.expects})" for loader in LOADERS)
    raise FileNotFoundError(f"{path}: no loader recognises it; known sources: {known}")
