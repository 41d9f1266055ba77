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
