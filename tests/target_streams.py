"""Candidate streams the event route used to refuse, made from a feng-probabilistic run (seed
000: a climber's camera sees a static ground robot's three markers, P3P candidates; the ground
robot at the world origin, so the climber's truth is its pose in the target's frame):

- `unplaced_target`: the target's initial_pose removed (its observer has none either);
- `placed_observer`: the climber given its true start pose, the target's initial_pose removed
  (max-mixtures place the target);
- `moving_target`: the ground robot drives (a planar path G(t), `relative_pose3` steps with
  noise) and the climber rides along (its pose G(t) C(t), so every candidate, camera-to-target,
  stays the one P3P solved; its steps C(t0)^-1 G(t0)^-1 G(t1) C(t0) composed with the logged
  step), the sets without marker pixels (`candidates` rows);
- `two_targets`: a second static ground robot at another pose with the same markers (its layout
  in its own frame), every other set of the climber's re-expressed as a set of it;
- `mixed_pixels`: every other set without its marker pixels.

Each keeps the truth of every robot it moves, so ATE and a static robot's error are measured;
`write_moving_target` writes the moving-target case as a log."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import gtsam
import numpy as np

from graphloc.candidates import CandidateSet
from graphloc.factors.surface import SurfacePlane
from graphloc.run import Motion

TARGET_STEP_SIGMAS = np.array([0.002, 0.002, 0.002, 0.004, 0.004, 0.004])  # rx ry rz tx ty tz


def _truth_at(run, r: int, t: float) -> gtsam.Pose3:
    times, poses = run.groundtruth[r]
    return poses[int(np.argmin(np.abs(np.asarray(times) - t)))]


def unplaced_target(run):
    """The static target without its initial_pose."""
    robots = tuple(replace(r, initial_pose=None) if r.static else r for r in run.robots)
    return replace(run, robots=robots)


def placed_observer(run):
    """The observer at its true start pose, the static target without an initial_pose, upright
    on the floor (its surface and attitude: the candidate whose body axis is the floor's normal
    places it, `mixtures.MixtureTracker`; its truth kept: the world origin)."""
    start = _truth_at(run, 0, run.start_time)
    floor = SurfacePlane(np.zeros(3), np.array([0.0, 0.0, 1.0]))
    robots = (
        replace(run.robots[0], initial_pose=start, initial_sigma=(0.01, 0.01)),
        replace(run.robots[1], initial_pose=None, surface=floor, attitude_sigma=0.05),
    )
    truth = (run.groundtruth[0], (np.array([run.start_time]), [gtsam.Pose3()]))
    return replace(run, robots=robots, groundtruth=truth)


def _path(t: float) -> gtsam.Pose3:
    """The moving target's planar path: 0.1 m/s along a slow left turn."""
    return gtsam.Pose3(gtsam.Rot3.Yaw(0.05 * t), np.array([0.1 * t, 0.02 * t * t, 0.0]))


def moving_target(run, seed: int = 0):
    """The target driving `_path`, the climber riding along, sets without pixels."""
    rng = np.random.default_rng(seed)
    cov = np.diag(TARGET_STEP_SIGMAS**2)
    times = np.unique([t for m in run.motions for t in (m.t0, m.t1)])
    steps = []
    for t0, t1 in zip(times[:-1], times[1:]):
        rel = _path(t0).between(_path(t1)).retract(rng.normal(0.0, TARGET_STEP_SIGMAS))
        steps.append(Motion(1, float(t0), float(t1), rel, cov))
    climber = []
    for m in run.motions:
        c0 = _truth_at(run, 0, m.t0)
        ride = c0.inverse().compose(_path(m.t0).between(_path(m.t1))).compose(c0)
        climber.append(replace(m, relative=ride.compose(m.relative)))
    gt_times, gt_poses = run.groundtruth[0]
    truth = (
        (gt_times, [_path(t).compose(p) for t, p in zip(gt_times, gt_poses)]),
        (gt_times, [_path(t) for t in gt_times]),
    )
    robots = (run.robots[0], replace(run.robots[1], static=False))
    motions = tuple(sorted(climber + steps, key=lambda m: (m.t1, m.robot)))
    observations = tuple(replace(o, pixels=None) for o in run.observations)
    return replace(
        run, robots=robots, motions=motions, observations=observations, groundtruth=truth
    )


SECOND = gtsam.Pose3(gtsam.Rot3.Yaw(0.7), np.array([0.4, -0.3, 0.0]))  # the second target


def _seen_from(o, pose: gtsam.Pose3, target: int):
    """Set `o` (candidates target_T_sensor of a target at the origin) as a set of `target` at
    `pose`: each candidate pose^-1 * candidate, its covariance (tangent at the sensor) kept."""
    c = o.candidates
    moved = [pose.inverse().compose(p) for p in c.poses()]
    R = np.stack([p.rotation().matrix() for p in moved])
    t = np.stack([p.translation() for p in moved])
    cs = CandidateSet(R, t, c.scores, c.time, c.observer, "ground2", c.source, c.meta, c.covariance)
    return replace(o, target=target, candidates=cs)


def two_targets(run):
    """A second static target (`SECOND`, the same markers in its frame), seen in every other
    set; its truth kept."""
    layout = np.array([SECOND.transformTo(p) for p in run.robots[1].markers])
    second = replace(run.robots[1], name="ground2", initial_pose=SECOND, markers=layout)
    observations = tuple(
        _seen_from(o, SECOND, 2) if i % 2 else o for i, o in enumerate(run.observations)
    )
    origin = (np.array([run.start_time]), [gtsam.Pose3()])
    truth = (run.groundtruth[0], origin, (origin[0], [SECOND]))
    return replace(
        run,
        robots=run.robots + (second,),
        observations=observations,
        groundtruth=truth,
        velocity=run.velocity + (np.zeros((0, 3)),),
    )


def mixed_pixels(run):
    """Every other set without its marker pixels."""
    observations = tuple(
        replace(o, pixels=None) if i % 2 else o for i, o in enumerate(run.observations)
    )
    return replace(run, observations=observations)


CASES = {
    "unplaced-target": unplaced_target,
    "placed-observer": placed_observer,
    "moving-target": moving_target,
    "two-targets": two_targets,
    "mixed-pixels": mixed_pixels,
}


def _pose_row(p: gtsam.Pose3) -> list:
    """tx ty tz qx qy qz qw of a pose."""
    q = p.rotation().toQuaternion()
    return [*p.translation(), q.x(), q.y(), q.z(), q.w()]


def write_moving_target(source: Path, out: Path, seed: int = 0) -> Path:
    """`moving_target` of the feng-probabilistic log at `source` written as a log at `out`
    (docs/log_format.md): both robots' `relative_pose3` steps, the climber's sets as
    `candidates` rows (target_T_sensor per candidate; their sigmas the manifest's
    `candidate_sigmas` default) and both robots' TUM ground truth."""
    from graphloc.datasets import open_run

    run = moving_target(open_run(source), seed)
    manifest = json.loads((source / "manifest.json").read_text())
    climber, ground = manifest["robots"]
    climber["tables"] = {
        "relative_pose3": "climber/relative_pose3.csv",
        "candidates": "climber/candidates.csv",
        "groundtruth": "climber/groundtruth.tum",
    }
    ground.pop("static")
    ground["sensors"] = [{"name": "odometry", "type": "odometry"}]
    ground["tables"] = {
        "relative_pose3": "ground/relative_pose3.csv",
        "groundtruth": "ground/groundtruth.tum",
    }
    for name in ("climber", "ground"):
        (out / name).mkdir(parents=True, exist_ok=True)
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1))
    for r, name in enumerate(("climber", "ground")):
        steps = [m for m in run.motions if m.robot == r]
        sig = [np.sqrt(np.diag(m.covariance)) for m in steps]
        rows = [[m.t1, "odometry", m.t0, *_pose_row(m.relative), *s] for m, s in zip(steps, sig)]
        columns = "time,sensor,time0,tx,ty,tz,qx,qy,qz,qw," + ",".join(
            f"sigma_{c}" for c in ("rx", "ry", "rz", "tx", "ty", "tz")
        )
        _write_csv(out / name / "relative_pose3.csv", columns, rows)
        times, poses = run.groundtruth[r]
        tum = [" ".join(repr(float(v)) for v in [t, *_pose_row(p)]) for t, p in zip(times, poses)]
        (out / name / "groundtruth.tum").write_text("\n".join(tum) + "\n")
    rows = []
    for o in run.observations:
        for k, (p, score) in enumerate(zip(o.candidates.poses(), o.candidates.scores)):
            t = _pose_row(p)
            rows.append([o.time, "camera", "ground", k, score, t[6], *t[3:6], *t[:3]])
    columns = "time,sensor,target,k,score,qw,qx,qy,qz,tx,ty,tz"
    _write_csv(out / "climber" / "candidates.csv", columns, rows)
    return out


def _write_csv(path: Path, header: str, rows: list) -> None:
    def text(v) -> str:
        return repr(float(v)) if isinstance(v, (float, np.floating)) else str(v)

    path.write_text("\n".join([header] + [",".join(map(text, row)) for row in rows]) + "\n")


def write_two_targets(source: Path, out: Path) -> Path:
    """`two_targets` as a log: the feng-probabilistic log at `source` copied to `out`, a second
    static robot `ground2` at `SECOND` with the same markers in its frame, and every other
    image's marker rows made rows of it (the same pixels: the same world points)."""
    import shutil

    shutil.copytree(source, out)
    manifest = json.loads((out / "manifest.json").read_text())
    ground = manifest["robots"][1]
    layout = [list(SECOND.transformTo(np.array(p, float))) for p in ground["markers"]]
    pose = _pose_row(SECOND)
    manifest["robots"].append(
        {**ground, "name": "ground2", "initial_pose": pose, "markers": layout}
    )
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1))
    path = out / "climber" / "markers.csv"
    header, *rows = path.read_text().splitlines()
    times = sorted({float(row.split(",")[0]) for row in rows})
    second = set(times[1::2])
    rows = [
        row.replace(",ground,", ",ground2,", 1) if float(row.split(",")[0]) in second else row
        for row in rows
    ]
    path.write_text("\n".join([header, *rows]) + "\n")
    return out
