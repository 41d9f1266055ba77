"""Map fusion on a simulated `dual-robot-room` (seed 004's setup): simulate, write the scenario
directory, fuse (`graphloc.pipelines.map_fusion.run.fuse_and_write`), write the outputs. Behind
`graphloc demo` (the README's main job: the furnished room) and `graphloc fuse-maps
--simulate`."""

from __future__ import annotations

from pathlib import Path

from graphloc.datasets.dual_room import DualRoomScenario, variant_config
from graphloc.pipelines.map_fusion.types import FusionConfig
from graphloc.pipelines.map_fusion.run import fuse_and_write


def simulate_and_fuse(
    out_dir,
    variant: str = "furnished",
    seed: int = 0,
    frames: int = 10,
    config: FusionConfig = FusionConfig(),
) -> dict:
    """Simulate `dual-robot-room` (written to out_dir/scenario), fuse, write outputs; returns
    the report."""
    scenario = DualRoomScenario.simulate(variant_config(variant, seed, frames=frames))
    out = Path(out_dir)
    scenario.write(out / "scenario")
    scenario_info = {
        "name": "dual-robot-room",
        "variant": variant,
        "seed": seed,
        "frames": frames,
        "dir": str(out / "scenario"),
        "counts": scenario.counts,
    }
    return fuse_and_write(
        scenario.fusion_input(),
        out,
        config,
        scenario.times,
        truth=scenario.T_ground0_ceiling0,
        extra={"scenario": scenario_info},
    )
