"""graphloc.datasets: run loaders behind one protocol (`loaders.open_run`) and the scenario
generators (`scenarios.Scenario`), registered by name; entries are imported lazily so that
`graphloc --help` does not pay for GTSAM, Open3D or rendering code.

    from graphloc.datasets import open_run, scenario_class
    run = open_run("../shared/data/mrclam/MRCLAM_Dataset6")"""

from __future__ import annotations

import importlib

# scenario name -> (module inside graphloc.datasets, class name)
SCENARIOS: dict[str, tuple[str, str]] = {
    "feng-probabilistic": ("feng", "FengProbabilisticScenario"),
    "crawler-pair": ("crawler_pair", "CrawlerPairScenario"),
    "dual-robot-room": ("dual_room", "DualRoomScenario"),
    "feng-deterministic": ("scenarios", "FengDeterministicScenario"),
    "kaushik-p3p-error": ("kaushik", "KaushikP3PErrorScenario"),
    "breitenmoser-target": ("breitenmoser", "BreitenmoserTargetScenario"),
}


def open_run(
    path, duration: float | None = None, noise: dict | None = None, source: dict | None = None
):
    """The loader factory (`graphloc.datasets.loaders.open_run`): a graphloc log, an MRCLAM
    directory, a ROS bag or a scan directory -> `graphloc.run.TeamRun`."""
    from graphloc.datasets.loaders import open_run as _open_run

    return _open_run(path, duration, noise, source)


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
