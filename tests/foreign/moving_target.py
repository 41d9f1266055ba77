"""The same marker pixels from a moving target and from a static one (issue 48: "on a moving
target, within 1.5x the error of the same pixels on a static one").

Two logs per seed, written with ``team_generator``'s pieces (from ``docs/log_format.md`` alone):

- ``static``: a ceiling robot (flat ceiling 3 m up, downward camera) drives on ``relative_pose3``
  over a static ground robot with a 4-marker layout and an ``initial_pose``;
- ``moving``: the ceiling robot stands still (``static``, ``initial_pose``) and the ground robot
  drives on ``relative_pose`` so that the camera-to-target pose is the static case's at every
  frame: G(t) = C0 C(t)^-1 G0. The marker pixels are drawn from one seeded generator in the same
  order in both logs, so they are the same pixels (jitter and noise); the odometry noise is drawn
  from another (the same sigmas on the planar components: ``relative_pose`` sigmas set to
  ``relative_pose3``'s x, y translation and yaw).

Both go through ``graphloc smooth`` and ``graphloc online`` (the CLI, as a user runs it); the
error compared is the relative pose camera robot -> ground robot at every camera frame, from the
two robots' TUM estimates against the truth: its translation RMS [m] and rotation RMS [deg].

``python tests/foreign/moving_target.py --out DIR [--graphloc .venv/bin/graphloc] [--seeds 0 1
2]`` writes ``DIR/moving_target.json`` and prints the table;
``tests/team_graph/test_foreign_runs.py`` holds the ratio.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

sys.path.insert(0, str(Path(__file__).resolve().parent))

import score  # noqa: E402
import team_generator as gen  # noqa: E402

RATIO = 1.5  # moving target's error at most this much the static one's (issue 48)
FRAME_S = 0.2  # camera frames and odometry steps


class PoseTrack(gen.Track):
    """A track given by a pose function of time (``planar`` read off a floor pose)."""

    def __init__(self, pose_of_time, static: bool = False):
        self._pose = pose_of_time
        self._static = static
        self.times = np.array([0.0])

    @property
    def static(self) -> bool:
        return self._static

    def pose(self, t: float) -> np.ndarray:
        return self._pose(t)

    def planar(self, t: float) -> np.ndarray:
        m = self._pose(t)
        return np.array([m[0, 3], m[1, 3], math.atan2(m[1, 0], m[0, 0])])


def build(seed: int, case: str, duration: float) -> tuple[gen.Log, dict]:
    """The log of ``case`` (static / moving) of ``seed`` and its generator config."""
    cfg = gen.GeneratorConfig(layout="ceiling-markers", seed=seed, camera_jitter_deg=(0.2, 0.5))
    noise = cfg.noise
    rel3 = noise.rel3_sigmas
    cfg = replace(cfg, noise=replace(noise, rel2_sigmas=(rel3[3], rel3[4], rel3[2])))
    shape = np.random.default_rng([seed, 0])  # the geometry: the same in both cases
    ceiling = gen.ceiling_plane(3.0, 0.0, 0.0)
    drive = gen.drive(shape, ceiling, (0.0, 0.0, shape.uniform(-3, 3)), duration, FRAME_S,
                      (-0.7, 0.7, -0.5, 0.5), 0.12, 0.5)  # fmt: skip
    layout = gen.marker_layout(shape, 4)
    c0 = ceiling.pose(0.0, 0.0, 0.3)
    g0 = np.eye(4)
    log = gen.Log(f"moving-target-{case}-s{seed}", [], duration=duration)
    pixels = gen.Sim(cfg, log, np.random.default_rng([seed, 1]))
    odometry = gen.Sim(cfg, log, np.random.default_rng([seed, 2]))
    surface = {"point": [0.0, 0.0, 3.0], "normal": [0.0, 0.0, -1.0]}
    if case == "static":
        cam = gen.Robot("ceiling", "ceiling", drive, planar=False, surface=surface)
        target = gen.Robot("rover", "ground", PoseTrack(lambda t: g0, static=True), planar=True,
                           static=True, markers=layout, initial_pose=True)  # fmt: skip
    elif case == "moving":
        cam = gen.Robot("ceiling", "ceiling", PoseTrack(lambda t: c0, static=True),
                        planar=False, static=True, initial_pose=True, surface=surface)  # fmt: skip
        moved = PoseTrack(lambda t: c0 @ gen.inverse(drive.pose(t)) @ g0)
        target = gen.Robot("rover", "ground", moved, planar=True, markers=layout)
    else:
        raise ValueError(f"case {case!r}: 'static' or 'moving'")
    camera = gen.camera_params(noise)
    pixels.mount(cam, "camera", "camera", [0.1, 0.0, 0.05], [0.03, -0.04, 0.5], camera)
    log.robots = [cam, target]
    frames = gen.frame_times(FRAME_S, duration)
    pixels.markers(cam, "camera", camera, ["rover"], frames)
    mover = cam if case == "static" else target
    odometry.odometry_sensor(mover)
    steps = gen.frame_times(FRAME_S, duration + FRAME_S)
    if case == "static":
        odometry.relative_pose3(mover, steps)
    else:
        odometry.relative_pose(mover, steps)
    return log, {"config": asdict(cfg), "conventions": gen.CONVENTIONS, "duration": duration}


def write(root: Path, seed: int, case: str, duration: float) -> Path:
    log, meta = build(seed, case, duration)
    run = root / f"{case}-s{seed}"
    gen.write_log(log, run, meta)
    return run


def _poses(times, xyz, quat, at) -> np.ndarray:
    """(len(at), 4, 4) poses of a TUM track at times ``at`` (one pose: held)."""
    out = np.tile(np.eye(4), (len(at), 1, 1))
    if len(times) == 1:
        out[:, :3, :3] = Rotation.from_quat(quat[0]).as_matrix()
        out[:, :3, 3] = xyz[0]
        return out
    at = np.clip(at, times[0], times[-1])
    out[:, :3, :3] = Slerp(times, Rotation.from_quat(quat))(at).as_matrix()
    out[:, :3, 3] = np.column_stack([np.interp(at, times, xyz[:, i]) for i in range(3)])
    return out


def relative_errors(run: Path, out: Path, mode: str) -> dict:
    """Translation RMS [m] and rotation RMS [deg] of the pose ceiling -> rover at every camera
    frame, the estimates' against the truth's."""
    truth = score.read_truth(run)
    frames = gen.frame_times(FRAME_S, json.loads((run / "generator.json").read_text())["duration"])
    rel = {}
    for which in ("estimate", "truth"):
        poses = {}
        for name in ("ceiling", "rover"):
            if which == "truth":
                tr = truth[name]
                poses[name] = _poses(tr["t"], tr["xyz"], tr["quat"], frames)
            else:
                t, xyz, quat = score.read_tum(out / f"{name}_{mode}.tum")
                if not len(t):
                    return {"unplaced": name}
                poses[name] = _poses(t, xyz, quat, frames)
        rel[which] = np.linalg.inv(poses["ceiling"]) @ poses["rover"]
    err = np.linalg.inv(rel["truth"]) @ rel["estimate"]
    trans = np.linalg.norm(err[:, :3, 3], axis=1)
    rot = np.degrees(Rotation.from_matrix(err[:, :3, :3]).magnitude())
    return {
        "translation_rms_m": float(np.sqrt(np.mean(trans**2))),
        "rotation_rms_deg": float(np.sqrt(np.mean(rot**2))),
        "frames": int(len(frames)),
    }


def run_case(graphloc: list[str], run: Path, out: Path, verb: str) -> dict:
    mode = "batch" if verb == "smooth" else "online"
    cmd = [*graphloc, verb, str(run), "--out", str(out), "--no-progress", "-q"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        return {"rc": proc.returncode, "error": proc.stderr[-500:]}
    metrics = json.loads((out / "metrics.json").read_text())
    return {"rc": 0, "consistent": metrics["consistent"], **relative_errors(run, out, mode)}


def compare(root: Path, graphloc: list[str], seeds, duration: float) -> dict:
    results = {}
    for seed in seeds:
        for case in ("static", "moving"):
            run = write(root / "runs", seed, case, duration)
            for verb in ("smooth", "online"):
                r = run_case(graphloc, run, root / "out" / f"{case}-s{seed}-{verb}", verb)
                results.setdefault(f"s{seed}", {}).setdefault(verb, {})[case] = r
                print(f"seed {seed} {case} {verb}: {r}", flush=True)
    for per_verb in results.values():
        for r in per_verb.values():
            s, m = r["static"], r["moving"]
            if "translation_rms_m" in s and "translation_rms_m" in m:
                r["ratio_translation"] = m["translation_rms_m"] / s["translation_rms_m"]
                r["ratio_rotation"] = m["rotation_rms_deg"] / s["rotation_rms_deg"]
    return results


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--graphloc", default=None, help="the command (default: this Python's)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--duration", type=float, default=40.0)
    args = parser.parse_args(argv)
    graphloc = [args.graphloc] if args.graphloc else [sys.executable, "-m", "graphloc"]
    results = compare(args.out, graphloc, args.seeds, args.duration)
    (args.out / "moving_target.json").write_text(json.dumps(results, indent=1) + "\n")
    print("| seed | verb | static: translation [m] / rotation [deg] | moving | ratio |")
    print("|---|---|---|---|---|")
    for seed, per_verb in results.items():
        for verb, r in per_verb.items():
            cells = [
                f"{r[c].get('translation_rms_m', float('nan')):.4f} / "
                f"{r[c].get('rotation_rms_deg', float('nan')):.3f}"
                for c in ("static", "moving")
            ]
            ratio = f"{r.get('ratio_translation', float('nan')):.2f} / " + (
                f"{r.get('ratio_rotation', float('nan')):.2f}"
            )
            print(f"| {seed} | {verb} | {cells[0]} | {cells[1]} | {ratio} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
