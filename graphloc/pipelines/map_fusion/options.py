"""`FuseMapsOptions`: the one option tree of `graphloc fuse-maps` -- its command-line options
and the keys of `--config FILE.toml` are these fields (`graphloc.config.add_config_arguments`
/ `config_from_args`). The pipeline's own settings are the nested `fusion` table
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

from dataclasses import dataclass, field

from graphloc.config import check
from graphloc.pipelines.map_fusion.config import FusionConfig


def _help(text: str) -> dict:
    return {"help": text}


@dataclass(frozen=True)
class FuseMapsOptions:
    hint: str | None = field(
        default=None,
        metadata=_help("with --ground: T_G0_C0 as 'x y z qx qy qz qw' or 16 numbers (row-major)"),
    )
    hint_sigma: str | None = field(
        default=None,
        metadata=_help("1-sigma of --hint: 'DEG M'; unset: the config's fusion.guess_sigma"),
    )
    p3p: str | None = field(
        default=None,
        metadata=_help("with --ground: camera + LED setup JSON with an LED pixel CSV (inputs.py)"),
    )
    rate: float = field(default=10.0, metadata=_help("frame rate of --ground / --ceiling [Hz]"))
    variant: str = field(
        default="furnished",
        metadata=_help("simulated room variant (furnished, empty, rectangular, low_overlap)"),
    )
    seed: int = field(default=0, metadata=_help("simulated room: scenario seed"))
    frames: int = field(default=10, metadata=_help("simulated room: frames per robot"))
    mcap: str | None = field(
        default=None, metadata=_help("also write the fused map and trajectories as MCAP")
    )
    rerun: str | None = field(default=None, metadata=_help("also write a Rerun recording (.rrd)"))
    fusion: FusionConfig = field(default_factory=FusionConfig)

    def __post_init__(self):
        check(
            self,
            integer={"seed": (0, 2**32 - 1), "frames": (1, 1000)},
            interval={"rate": (0.0, 1000.0, "(]")},
        )
        if self.hint_sigma is not None and self.hint is None:
            raise ValueError("FuseMapsOptions.hint_sigma needs hint (--hint-sigma needs --hint)")
        if self.hint is not None and self.p3p is not None:
            raise ValueError("FuseMapsOptions: give hint or p3p, not both (--hint / --p3p)")
