"""graphloc.datasets: run loaders behind one protocol (`loaders.open_run`) and the scenario
generators (`scenarios.Scenario`), registered by name; entries are imported lazily so that
`graphloc --help` does not pay for GTSAM, Open3D or rendering code.

    from graphloc.datasets import open_run, scenario_class
    run = open_run("../shared/data/mrclam/MRCLAM_Dataset6")"""

from __future__ import annotations

import importlib

from graphloc import lazy_api

# scenario name -> (module inside graphloc.datasets, class name)
SCENARIOS: dict[str, tuple[str, str]] = {
    "feng-probabilistic": ("feng", "FengProbabilisticScenario"),
    "crawler-pair": ("crawler_pair", "CrawlerPairScenario"),
    "dual-robot-room": ("dual_room", "DualRoomScenario"),
    "feng-deterministic": ("scenarios", "FengDeterministicScenario"),
    "kaushik-p3p-error": ("kaushik", "KaushikP3PErrorScenario"),
    "breitenmoser-target": ("breitenmoser", "BreitenmoserTargetScenario"),
}

# the loader factory (`loaders.open_run`: a graphloc log, an MRCLAM directory, a ROS bag or a
# scan directory -> `graphloc.run.TeamRun`), loaded on first use
__getattr__, __dir__ = lazy_api(__name__, {"open_run": "graphloc.datasets.loaders"})


def scenario_names() -> list[str]:
    return sorted(SCENARIOS)


def scenario_class(name: str):
    """The scenario class registered under `name`; ValueError naming the scenarios otherwise."""
    try:
        module_name, class_name = SCENARIOS[name]
    except KeyError:
        raise ValueError(
            f"unknown scenario {name!r}; scenarios: {', '.join(scenario_names())}"
        ) from None
    module = importlib.import_module(f"graphloc.datasets.{module_name}")
    return getattr(module, class_name)
