"""The consistency verdict of every solve (`judge`): per factor type and robot the normalized
chi-square without the robust kernels and the share down-weighted, per candidate stream the
share of inconsistent sets, and warnings for what the solve could not use (docs/outputs.md)."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np

from graphloc.config_schema import config_dataclass, setting

# skip reasons that drop rows a log states (docs/log_format.md): each is a warning (not
# `too_few_markers`: a frame where markers left the image is no fault of the log)
LOST_ROWS = (
    "field_count",
    "parse",
    "non_finite",
    "implausible",
    "field_too_long",
    "time_backwards",
    "unknown_sensor",
    "sensor_type",
    "unknown_target",
    "path_outside_run",
    "bad_relative_pose",
    "not_unit",
    "non_positive_range",
    "self_observation",
    "unknown_marker",
    "duplicate_marker",
    "no_p3p_solution",
    "no_pose_at_time",
    "target_unplaced",
    "unplaced_camera",
    "bad_pixel",
)


MIN_DIM = 20  # residual dimensions a robot's factors of one type need to be judged on their own


@config_dataclass
class ConsistencyTest:
    """The thresholds of the verdict (module docstring)."""

    max_normalized_chi2: float = setting(4.0, gt=0.0)
    max_downweighted_share: float = setting(0.1, ge=0.0, le=1.0)
    max_inconsistent_share: float = setting(0.1, ge=0.0, le=1.0)
    # pose-graph files: of the measurements a file marks as possible outliers, the share a
    # solve may decide outliers (`commands.pose_graph_run.verdict`); such files come with many
    max_null_share: float = setting(0.5, ge=0.0, le=1.0)


def factor_statistics(res, types: np.ndarray, threshold: float, select=None) -> dict:
    """Per factor type (graph order `types`; of the factors `select` holds, all by default): count,
    residual dimension, chi-square without the robust kernel (`factors.robust.residuals`), robust
    factors and those down-weighted below `threshold`, and over the others (the inliers) the
    whitened residual RMS and normalized chi-square (chi2 / dim)."""
    out = {}
    muted = res.downweighted(threshold)
    chosen = np.ones(len(types), bool) if select is None else np.asarray(select, bool)
    for kind in sorted(set(types[chosen].tolist())):
        sel = (types == kind) & chosen
        inliers = sel & ~muted
        dim, chi2 = int(res.dims[sel].sum()), float(res.chi2[sel].sum())
        dim_in, chi2_in = int(res.dims[inliers].sum()), float(res.chi2[inliers].sum())
        robust, down = int(res.robust[sel].sum()), int(muted[sel].sum())
        out[kind] = {
            "count": int(sel.sum()),
            "dim": dim,
            "chi2": chi2,
            "rms": float(np.sqrt(chi2_in / dim_in)) if dim_in else None,
            "normalized_chi2": chi2_in / dim_in if dim_in else None,
            "robust": robust,
            "downweighted": down,
            "downweighted_share": down / robust if robust else 0.0,
        }
    return out


def robot_statistics(res, types: np.ndarray, owners: np.ndarray, names: list, threshold):
    """`factor_statistics` per robot: the factors whose first pose (else marker point) is the
    robot's -- its odometry and surface, what its sensors measured, its markers' layout --
    {robot name: {type: row}}."""
    return {
        names[r]: factor_statistics(res, types, threshold, owners == r)
        for r in sorted(set(owners.tolist()))
        if r >= 0
    }


def candidate_streams(decisions: list, names: list) -> dict:
    """Per (observer, target) stream "observer->target": its sets, decided, undecided and
    inconsistent ones."""
    out: dict = {}
    for d in decisions:
        row = out.setdefault(
            f"{names[d.robot]}->{names[d.target]}",
            {"sets": 0, "decided": 0, "undecided": 0, "inconsistent": 0},
        )
        row["sets"] += 1
        row[d.status] += 1
    return out


def judge(
    factor_stats: dict,
    streams: dict,
    unplaced: list,
    skips: dict,
    test: ConsistencyTest = ConsistencyTest(),
    robot_stats: dict | None = None,
) -> dict:
    """The verdict {"consistent", "test", "failures", "warnings"} of `factor_statistics`,
    `robot_statistics` (a robot's factors of one type judged alone from MIN_DIM residual
    dimensions), `candidate_streams`, the names of robots left `unplaced` and the skips
    (`SkipReport.as_dict()`)."""
    failures, warnings = [], []
    groups = [("", factor_stats)] + [
        (f"robot {name}: ", rows) for name, rows in (robot_stats or {}).items()
    ]
    for prefix, rows in groups:
        for kind, row in rows.items():
            nchi2 = row["normalized_chi2"]
            if prefix and row["dim"] < MIN_DIM:
                continue
            if nchi2 is not None and nchi2 > test.max_normalized_chi2:
                failures.append(
                    f"{prefix}{kind} factors: normalized chi-square {nchi2:.3g} > "
                    f"{test.max_normalized_chi2:g} (whitened residual RMS {row['rms']:.3g}; "
                    f"{row['count']} factors)"
                )
            if row["robust"] and row["downweighted_share"] > test.max_downweighted_share:
                failures.append(
                    f"{prefix}{kind} factors: {row['downweighted']} of {row['robust']} "
                    f"down-weighted by the robust kernel ({row['downweighted_share']:.0%} > "
                    f"{test.max_downweighted_share:.0%})"
                )
    for name, row in streams.items():
        share = row["inconsistent"] / row["sets"]
        if share > test.max_inconsistent_share:
            failures.append(
                f"candidate sets {name}: {row['inconsistent']} of {row['sets']} inconsistent "
                f"(no pose of the target's layout explains the marker pixels; {share:.0%} > "
                f"{test.max_inconsistent_share:.0%})"
            )
        if row["decided"] == 0 and row["sets"] > row["inconsistent"]:
            warnings.append(
                f"candidate sets {name} (markers / candidates / ellipses table of "
                f"{name.split('->')[0]}): none of {row['sets']} decided"
            )
    for name in unplaced:
        warnings.append(f"robot {name}: left unplaced (nothing anchors it; its poses are absent)")
    first = skips.get("first", {})
    for reason, count in sorted(skips.get("counts", {}).items()):
        if reason in LOST_ROWS:
            example = first.get(reason, "")
            warnings.append(
                f"{count} rows skipped ({reason})" + (f", e.g. {example}" if example else "")
            )
    return {
        "consistent": not failures,
        "test": asdict(test),
        "failures": failures,
        "warnings": warnings,
    }
