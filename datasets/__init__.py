"""graphloc.datasets (source folder datasets/): named loaders and scenario generators, one
class each, in the style of KISS-ICP's dataset registry. Entries are imported lazily so that
`graphloc --help` does not pay for Open3D or rendering code.

    from graphloc.datasets import dataset_class, available
    cls = dataset_class("mrclam")
"""

from __future__ import annotations

import importlib

# name -> (module inside graphloc.datasets, class name)
_REGISTRY: dict[str, tuple[str, str]] = {
    "feng-probabilistic": ("feng", "FengProbabilisticScenario"),
    "crawler-pair": ("crawler_pair", "CrawlerPairScenario"),
    "mrclam": ("mrclam", "MRCLAM"),
    "dual-robot-room": ("dual_room", "DualRoomScenario"),
    "feng-deterministic": ("scenarios", "FengDeterministicScenario"),
    "kaushik-p3p-error": ("kaushik", "KaushikP3PErrorScenario"),
    "breitenmoser-target": ("breitenmoser", "BreitenmoserTargetScenario"),
}


def open_run(path, duration: float | None = None, noise: dict | None = None):
    """The loader factory: a graphloc log directory (manifest.json, format version 1 or 2) or
    an MRCLAM dataset directory -> `graphloc.run.TeamRun`, optionally cut to the first
    `duration` seconds. `noise`: sensor noise (bearing_sigma, range_sigma, range_sigma_per_m,
    pixel_sigma) replacing what the log states (a config file or CLI flags)."""
    from pathlib import Path

    from graphloc.io import MANIFEST
    from graphloc.run import read_team_run, team_run_from_planar, truncate

    path = Path(path)
    if (path / MANIFEST).is_file():
        run = read_team_run(path, overrides=noise)
    else:
        from graphloc.datasets.mrclam import MRCLAM, is_mrclam_dir

        if not is_mrclam_dir(path):
            raise FileNotFoundError(f"{path}: neither a graphloc log (no {MANIFEST}) nor an MRCLAM directory "
                                    f"(no Barcodes.dat)")
        run = team_run_from_planar(MRCLAM(path, duration=duration).load(), noise)
    return run if duration is None else truncate(run, duration)


def available() -> list[str]:
    return sorted(_REGISTRY)


def dataset_class(name: str):
    """The loader / scenario class registered under `name`."""
    try:
        module_name, class_name = _REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown dataset or scenario {name!r}; available: {', '.join(available())}") from None
    module = importlib.import_module(f"graphloc.datasets.{module_name}")
    return getattr(module, class_name)
