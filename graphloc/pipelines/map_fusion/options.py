"""`FuseMapsOptions`: the one option tree of `graphloc fuse-maps` -- its command-line options
and the keys of `--config FILE.toml` are these fields (`graphloc.config.add_config_arguments`
/ `config_from_args`; their rules are pydantic field constraints). The pipeline's own settings
are the nested `fusion` table
(`FusionConfig`: `[fusion]` for its scalars, `[fusion.registration]`, `[fusion.acceptance]`,
`[fusion.odometry]`, `[fusion.tracker]`, `[fusion.session]` for its parts):

    rate = 10.0                     # top level: the options of the command line
    [fusion]
    guess_sigma = [0.0873, 0.1]     # 1-sigma of a hint given without its own: rot [rad], m
    [fusion.registration]           # graphloc.mapping.registration.RegistrationConfig
    voxel = 0.03
    [fusion.acceptance]             # graphloc.mapping.acceptance.AcceptanceConfig
    min_inlier_ratio = 0.65
"""

from __future__ import annotations

from dataclasses import field

from graphloc.config_schema import config_dataclass, setting
from graphloc.pipelines.map_fusion.config import FusionConfig


@config_dataclass
class FuseMapsOptions:
    hint: str | None = setting(
        None,
        description="with --ground: T_G0_C0 as 'x y z qx qy qz qw' or 16 numbers (row-major)",
    )
    hint_sigma: str | None = setting(
        None,
        description="1-sigma of --hint: 'DEG M'; unset: the config's fusion.guess_sigma",
    )
    p3p: str | None = setting(
        None,
        description="with --ground: camera + LED setup JSON with an LED pixel CSV (inputs.py)",
    )
    rate: float = setting(
        10.0, gt=0.0, le=1000.0, description="frame rate of --ground / --ceiling [Hz]"
    )
    variant: str = setting(
        "furnished",
        description="simulated room variant (furnished, empty, rectangular, low_overlap)",
    )
    seed: int = setting(0, ge=0, le=2**32 - 1, description="simulated room: scenario seed")
    frames: int = setting(10, ge=1, le=1000, description="simulated room: frames per robot")
    mcap: str | None = setting(
        None,
        description="also write the fused map and trajectories as MCAP",
    )
    rerun: str | None = setting(None, description="also write a Rerun recording (.rrd)")
    fusion: FusionConfig = field(default_factory=FusionConfig)

    def __post_init__(self):
        if self.hint_sigma is not None and self.hint is None:
            raise ValueError("FuseMapsOptions.hint_sigma needs hint (--hint-sigma needs --hint)")
        if self.hint is not None and self.p3p is not None:
            raise ValueError("FuseMapsOptions: give hint or p3p, not both (--hint / --p3p)")
