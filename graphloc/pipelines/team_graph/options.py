"""`RunOptions`: the one option tree of `graphloc smooth`, `online` and `validate` (command-line
options, `--config` keys and metrics.json's "options"), turned into the loader's options, the
noise overrides and the `GraphConfig`. Light (no GTSAM), with the online lag's default."""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

from graphloc.config_schema import config_dataclass, setting
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


@config_dataclass
class RunOptions:
    duration: float | None = setting(
        None,
        gt=0.0,
        le=MAX_TIME,
        description="use only the first N seconds; unset: all",
    )
    topics: str | None = setting(
        None,
        description=(
            "a bag run's topics file (YAML, docs/rosbag.md); unset: topics.yaml inside or "
            "beside the bag"
        ),
    )
    scan_rate: float | None = setting(
        None,
        gt=0.0,
        le=1000.0,
        description="a scan directory without a times file: scans per second [Hz]; unset: 10",
    )
    candidate_seed: int | None = setting(
        None,
        ge=0,
        le=2**32 - 1,
        description=(
            "a pose-graph file (City10000 / g2o): shuffle each measurement's candidates with "
            "this seed; its first-listed candidate is then the truth (mode accuracy)"
        ),
    )
    null_loops: bool | None = setting(
        None,
        description="a pose-graph file: every loop closure may be an outlier (null component)",
    )
    truth_poses: str | None = setting(
        None,
        description=(
            "a pose-graph file: its ground-truth poses, one line per pose id (x y theta, or "
            "x y z qx qy qz qw)"
        ),
    )
    keyframe_dt: float = setting(
        0.25,
        ge=1e-3,
        le=3600.0,
        description="pose grid of wheel-odometry robots [s]",
    )
    sync_tolerance: float = setting(
        0.02,
        gt=0.0,
        le=60.0,
        description=(
            "largest time offset between a measurement and its pose [s] (robots without wheel "
            "odometry)"
        ),
    )
    landmarks: bool = setting(True, description="use landmark measurements")
    inter_robot: bool = setting(True, description="use robot-to-robot measurements")
    unknown_landmarks: bool = setting(
        False,
        description="cooperative SLAM: estimate landmark positions instead of using the map",
    )
    kernel: str = setting(
        "cauchy:2.0",
        description=(
            "robust kernel NAME[:k] of landmark and inter-robot factors (huber, cauchy, tukey, "
            "gemanmcclure, dcs, none)"
        ),
    )
    odometry_kernel: str = setting(
        "none",
        description="robust kernel NAME[:k] of odometry factors",
    )
    candidate_kernel: str = setting(
        "cauchy:1.0",
        description="robust kernel NAME[:k] of decided candidate sets",
    )
    bearing_sigma: float | None = setting(
        None,
        gt=0.0,
        le=MAX_SIGMA,
        description="bearing noise [rad] of every sensor; unset: the log's",
    )
    range_sigma: float | None = setting(
        None,
        gt=0.0,
        le=MAX_SIGMA,
        description="range noise at 0 m [m]; unset: the log's",
    )
    range_sigma_per_m: float | None = setting(
        None,
        ge=0.0,
        le=MAX_SIGMA,
        description="range noise growth [m per m]; unset: the log's",
    )
    pixel_sigma: float | None = setting(
        None,
        gt=0.0,
        le=MAX_SIGMA,
        description="pixel noise [px] of every camera; unset: the log's",
    )
    lag: float | None = setting(
        None,
        ge=0.0,
        le=MAX_TIME,
        description=(
            f"online: fixed-lag window [s], 0 = full smoothing; unset: {DEFAULT_LAG:g} s where "
            "no variable must outlive it, else 0 (docs/outputs.md)"
        ),
    )
    mcap: str | None = setting(
        None,
        description="also write the results as an MCAP file (Foxglove, RViz)",
    )
    rerun: str | None = setting(
        None,
        description="also write a Rerun recording (.rrd; graphloc[viz])",
    )
    groundtruth_rate: Literal[GROUNDTRUTH_RATES] = setting(
        "estimate",
        description=(
            "<robot>_groundtruth.tum: 'estimate' (the samples matched to the robot's pose "
            "times, those the metrics compare) or 'full' (every sample)"
        ),
    )
    align: Literal[ALIGNMENTS] | None = setting(
        None,
        description=(
            "how estimates are compared with ground truth: none, se2, se3 or sim3 (evo's "
            "names); unset: the world frame when the log anchors it, else se2 / se3"
        ),
    )
    strict: bool = setting(
        False,
        description=(
            "exit with code 5 when the solve is inconsistent or a warning was raised "
            "(docs/outputs.md)"
        ),
    )

    def __post_init__(self):
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

    def graph_config(self, run=None) -> GraphConfig:
        """The `GraphConfig` of these options; with `run`, its online lag set (`lag`, else the
        default policy, `config.default_lag`)."""
        from dataclasses import replace

        from graphloc.pipelines.team_graph.config import GraphConfig, default_lag

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
        config = GraphConfig(
            keyframe_dt=self.keyframe_dt,
            sync_tolerance=self.sync_tolerance,
            use_landmarks=self.landmarks,
            use_inter_robot=self.inter_robot,
            landmark_priors=not self.unknown_landmarks,
            kernels=kernels,
        )
        if run is None:
            return config
        lag = self.lag if self.lag is not None else default_lag(run, config)
        return replace(config, lag=float(lag))
