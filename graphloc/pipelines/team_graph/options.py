"""`RunOptions`: the one option tree of `graphloc smooth`, `online` and `validate` -- the
command-line options, the `--config FILE.toml` keys and the `metrics.json` "options" are its
fields (`graphloc.config.add_config_arguments` / `config_from_args`). What it turns into: the
loader's `duration`, source options (`source`: a bag's topics file, a scan directory's rate)
and sensor-noise overrides (`noise`), the `GraphConfig` (`graph_config`), the online lag and
the extra outputs. Light (no GTSAM): the command line's options derive from it, and the online
lag's default (`DEFAULT_LAG`, the policy in `team_graph.config.default_lag`) is stated here."""

from __future__ import annotations

from dataclasses import dataclass, field

from typing import TYPE_CHECKING

from graphloc.config import check
from graphloc.records import MAX_SIGMA, MAX_TIME
from graphloc.factors.robust import Kernel, KernelPolicy

if TYPE_CHECKING:
    from graphloc.pipelines.team_graph.config import GraphConfig

NOISE = ("bearing_sigma", "range_sigma", "range_sigma_per_m", "pixel_sigma")
KERNELS = ("kernel", "odometry_kernel", "candidate_kernel")
OUTPUTS = ("mcap", "rerun", "groundtruth_rate", "align", "strict")  # `validate` leaves them out
# what <robot>_groundtruth.tum holds (graphloc.pipelines.report.groundtruth_written)
GROUNDTRUTH_RATES = ("estimate", "full")
# how estimates meet ground truth: graphloc.eval.ALIGNMENTS (evo's names), here without evo
ALIGNMENTS = ("none", "se2", "se3", "sim3")
SOLVER = ("lag",)
SOURCE = ("topics", "scan_rate")  # options of one kind of source (open_run's `source`)
# options of a pose-graph file (City10000 / g2o: graphloc.commands.pose_graph_run)
POSE_GRAPH = ("candidate_seed", "null_loops", "truth_poses")
DEFAULT_LAG = 45.0  # [s] online fixed-lag window (scripts/bench_scale.py measures the choice)


def _help(text: str) -> dict:
    return {"help": text}


@dataclass(frozen=True)
class RunOptions:
    duration: float | None = field(
        default=None, metadata=_help("use only the first N seconds; unset: all")
    )
    topics: str | None = field(
        default=None,
        metadata=_help(
            "a bag run's topics file (YAML, docs/rosbag.md); unset: topics.yaml inside or "
            "beside the bag"
        ),
    )
    scan_rate: float | None = field(
        default=None,
        metadata=_help("a scan directory without a times file: scans per second [Hz]; unset: 10"),
    )
    candidate_seed: int | None = field(
        default=None,
        metadata=_help(
            "a pose-graph file (City10000 / g2o): shuffle each measurement's candidates with "
            "this seed; its first-listed candidate is then the truth (mode accuracy)"
        ),
    )
    null_loops: bool | None = field(
        default=None,
        metadata=_help("a pose-graph file: every loop closure may be an outlier (null component)"),
    )
    truth_poses: str | None = field(
        default=None,
        metadata=_help(
            "a pose-graph file: its ground-truth poses, one line per pose id (x y theta, or "
            "x y z qx qy qz qw)"
        ),
    )
    keyframe_dt: float = field(
        default=0.25, metadata=_help("pose grid of wheel-odometry robots [s]")
    )
    sync_tolerance: float = field(
        default=0.02,
        metadata=_help(
            "largest time offset between a measurement and its pose [s] (robots without wheel "
            "odometry)"
        ),
    )
    landmarks: bool = field(default=True, metadata=_help("use landmark measurements"))
    inter_robot: bool = field(default=True, metadata=_help("use robot-to-robot measurements"))
    unknown_landmarks: bool = field(
        default=False,
        metadata=_help("cooperative SLAM: estimate landmark positions instead of using the map"),
    )
    kernel: str = field(
        default="cauchy:2.0",
        metadata=_help(
            "robust kernel NAME[:k] of landmark and inter-robot factors (huber, cauchy, tukey, "
            "gemanmcclure, dcs, none)"
        ),
    )
    odometry_kernel: str = field(
        default="none", metadata=_help("robust kernel NAME[:k] of odometry factors")
    )
    candidate_kernel: str = field(
        default="cauchy:1.0", metadata=_help("robust kernel NAME[:k] of decided candidate sets")
    )
    bearing_sigma: float | None = field(
        default=None, metadata=_help("bearing noise [rad] of every sensor; unset: the log's")
    )
    range_sigma: float | None = field(
        default=None, metadata=_help("range noise at 0 m [m]; unset: the log's")
    )
    range_sigma_per_m: float | None = field(
        default=None, metadata=_help("range noise growth [m per m]; unset: the log's")
    )
    pixel_sigma: float | None = field(
        default=None, metadata=_help("pixel noise [px] of every camera; unset: the log's")
    )
    lag: float | None = field(
        default=None,
        metadata=_help(
            f"online: fixed-lag window [s], 0 = full smoothing; unset: {DEFAULT_LAG:g} s where "
            "no variable must outlive it, else 0 (docs/outputs.md)"
        ),
    )
    mcap: str | None = field(
        default=None, metadata=_help("also write the results as an MCAP file (Foxglove, RViz)")
    )
    rerun: str | None = field(
        default=None, metadata=_help("also write a Rerun recording (.rrd; graphloc[viz])")
    )
    groundtruth_rate: str = field(
        default="estimate",
        metadata=_help(
            "<robot>_groundtruth.tum: 'estimate' (the samples matched to the robot's pose "
            "times, those the metrics compare) or 'full' (every sample)"
        ),
    )
    align: str | None = field(
        default=None,
        metadata=_help(
            "how estimates are compared with ground truth: none, se2, se3 or sim3 (evo's "
            "names); unset: the world frame when the log anchors it, else se2 / se3"
        ),
    )
    strict: bool = field(
        default=False,
        metadata=_help(
            "exit with code 5 when the solve is inconsistent or a warning was raised "
            "(docs/outputs.md)"
        ),
    )

    def __post_init__(self):
        check(
            self,
            interval={
                "keyframe_dt": (1e-3, 3600.0, "[]"),  # s: a pose grid from 1 kHz to an hour
                "sync_tolerance": (0.0, 60.0, "(]"),  # s
                "scan_rate": (0.0, 1000.0, "(]"),  # Hz
                "lag": (0.0, MAX_TIME, "[]"),
                **{s: (0.0, MAX_SIGMA, "(]") for s in NOISE if s != "range_sigma_per_m"},
                "range_sigma_per_m": (0.0, MAX_SIGMA, "[]"),
            },
            integer={"candidate_seed": (0, 2**32 - 1)},
            optional=("duration", "bearing_sigma", "range_sigma", "range_sigma_per_m")
            + ("pixel_sigma", "lag", "scan_rate", "align", "candidate_seed"),
            choices={"groundtruth_rate": GROUNDTRUTH_RATES, "align": ALIGNMENTS},
        )
        if self.duration is not None and not 0 < self.duration <= MAX_TIME:
            raise ValueError(
                f"RunOptions.duration must be > 0 and at most {MAX_TIME:g} s, got {self.duration}"
            )
        for name in KERNELS:
            try:
                Kernel.parse(getattr(self, name))
            except ValueError as exc:
                raise ValueError(f"RunOptions.{name} (--{name.replace('_', '-')}): {exc}") from None
        if not (self.landmarks or self.inter_robot):
            raise ValueError("--no-landmarks with --no-inter-robot leaves only odometry")

    def source(self) -> dict:
        """Options of one kind of source that were set (`graphloc.datasets.open_run`'s
        `source`): a bag's topics file, a scan directory's rate."""
        return {k: getattr(self, k) for k in SOURCE if getattr(self, k) is not None}

    def pose_graph(self) -> dict:
        """Options of a pose-graph file that were set (`graphloc.commands.pose_graph_run`)."""
        return {k: getattr(self, k) for k in POSE_GRAPH if getattr(self, k) is not None}

    def noise(self) -> dict:
        """Sensor noise that replaces what the log's sensor params say."""
        return {k: getattr(self, k) for k in NOISE if getattr(self, k) is not None}

    def graph_config(self) -> GraphConfig:
        from graphloc.pipelines.team_graph.config import GraphConfig

        kernel = Kernel.parse(self.kernel)
        kernels = KernelPolicy(
            {
                **GraphConfig().kernels.by_type,
                "landmark": kernel,
                "inter_robot": kernel,
                "candidate": Kernel.parse(self.candidate_kernel),
                "odometry": Kernel.parse(self.odometry_kernel),
            }
        )
        return GraphConfig(
            keyframe_dt=self.keyframe_dt,
            sync_tolerance=self.sync_tolerance,
            use_landmarks=self.landmarks,
            use_inter_robot=self.inter_robot,
            landmark_priors=not self.unknown_landmarks,
            kernels=kernels,
        )
