"""Live latency (issue 50), on MRCLAM Dataset6 (`../shared/data/mrclam/MRCLAM_Dataset6`, its
first `duration` seconds as a log: `graphloc.log_writer.write_planar_run`):

- per-step latency against the team size: teams of 1, 2 and 5 of its robots and of 10 (its
  five and a renamed copy of them, observing the copies where the originals observe each
  other: `team_log`) replayed through the live API in time order (`graphloc.live.
  replay_live`); each update's latency (`LiveUpdate.latency_s`: the step's iSAM2 update and
  every new pose's marginal covariance) -> p50 / p95 / max;
- end to end, the five robots: this process publishes the log's rows over Cyclone DDS (on the
  loopback interface) at their recorded pace as `graphloc_msgs/msg/LogRow`, a `graphloc live
  --ros2 --manifest LOG --publish` process localizes them and publishes each robot's pose, and
  this process reads the poses back. MRCLAM's rows (unicycle velocities, planar
  range-bearing) have no standard ROS message that keeps them as they are: a topics file
  would turn them into relative poses and unit bearings, another estimation problem than
  `graphloc online`'s on the same run, so the rows go out as their log lines. An update
  happens while the row that completes its step is pushed (its trigger, OUT/live_updates.csv);
  a pose's end-to-end latency is the time from the trigger's publication here to that pose's
  reception here (one clock, CLOCK_MONOTONIC), split into the way in (publication -> arrival
  in graphloc live), the update (arrival -> the update's poses and covariances ready) and the
  way out (-> reception, through the ROS 2 sink); the update split further by the times
  `graphloc live` logs per trigger: queued for the run loop, before the step (the trigger's
  checks and graph building, and the earlier steps of the same push for a step that is not
  the first a row completes), the step itself (iSAM2 and covariances, wall and CPU time) and
  the sinks (the poses published). Its age is the time from the publication of
  the robot's newest row at the pose's time to the pose's reception: the end-to-end latency
  plus the wait for the rows that complete the step (the late-row window, the other robots'
  rows up to that time). Measured with the window 0 (rows in time order on one machine) and
  0.5 s (the default).

All numbers come from one run on this machine, shared with other work (the load average is
recorded): absolute times, to be read with it."""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATASET6 = ROOT.parent / "shared" / "data" / "mrclam" / "MRCLAM_Dataset6"
TEAM_SIZES = (1, 2, 5, 10)
TARGET_P95_S = 0.020  # issue 50: end-to-end p95 for Dataset6's five robots
CYCLONE_LO = (
    "<CycloneDDS><Domain Id='any'><General><Interfaces><NetworkInterface name='lo'/>"
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
    "<ParticipantIndex>auto</ParticipantIndex><Peers><Peer Address='127.0.0.1'/></Peers>"
    "</Discovery></Domain></CycloneDDS>"
)


def stats(values) -> dict:
    """n, p50, p95, max of `values` (empty: n 0 only)."""
    a = np.asarray(values, dtype=float)
    if not len(a):
        return {"n": 0}
    return {
        "n": int(len(a)),
        "p50": float(np.percentile(a, 50)),
        "p95": float(np.percentile(a, 95)),
        "max": float(a.max()),
    }


def team_log(src: Path, out: Path, size: int) -> Path:
    """A log of `size` robots of the log `src` (its first robots; 10: all five and a copy of
    them named NAME_b, whose range-bearing rows to robots target the copies). Rows measuring a
    robot not in the team are left out."""
    manifest = json.loads((src / "manifest.json").read_text())
    names = [r["name"] for r in manifest["robots"]]
    copies = 2 if size > len(names) else 1
    if copies == 2 and size != 2 * len(names):
        raise ValueError(f"a team of {size} from {len(names)} robots: up to {len(names)} or 2x")
    chosen = names[: min(size, len(names))]
    robots = []
    out.mkdir(parents=True, exist_ok=True)
    for c in range(copies):
        suffix = "" if c == 0 else "_b"
        rename = {n: n + suffix for n in chosen}
        for r in manifest["robots"]:
            if r["name"] not in chosen:
                continue
            new = {**r, "name": rename[r["name"]], "tables": {}}
            for table, rel in r["tables"].items():
                dst = f"{new['name']}/{Path(rel).name}"
                (out / dst).parent.mkdir(parents=True, exist_ok=True)
                _copy_table(src / rel, out / dst, rename, set(names) - set(chosen))
                new["tables"][table] = dst
            robots.append(new)
    for key in ("landmarks",):
        if key in manifest:
            shutil.copy(src / manifest[key]["file"], out / manifest[key]["file"])
    (out / "manifest.json").write_text(json.dumps({**manifest, "robots": robots}, indent=1))
    return out


def _copy_table(src: Path, dst: Path, rename: dict, dropped: set) -> None:
    with open(src, newline="") as fi, open(dst, "w", newline="") as fo:
        rows = csv.reader(fi)
        w = csv.writer(fo)
        header = next(rows)
        w.writerow(header)
        k = header.index("target") if "target" in header else None
        for row in rows:
            if k is not None:
                if row[k] in dropped:
                    continue
                row[k] = rename.get(row[k], row[k])
            w.writerow(row)


def step_latency(log: Path, window: float = 0.5) -> dict:
    """The live API's per-update latency replaying `log` in time order (`replay_live`)."""
    from graphloc.live import replay_live

    latencies = []
    t0 = time.perf_counter()
    team = replay_live(log, None, window, subscriber=lambda u: latencies.append(u.latency_s))
    wall = time.perf_counter() - t0
    return {
        "robots": len(team.names),
        "steps": len(latencies),
        "wall_s": wall,
        "latency_s": stats(latencies),
        "skipped": team.skips.total,
    }


def lo_only_environment(domain: int) -> dict:
    """The environment of a run on the loopback interface in its own DDS domain (a Cyclone
    configuration file written to a temporary folder)."""
    cfg = Path(tempfile.mkdtemp(prefix="graphloc-live-bench-")) / "cyclonedds.xml"
    cfg.write_text(CYCLONE_LO)
    return {"CYCLONEDDS_URI": cfg.as_uri(), "ROS_DOMAIN_ID": str(domain)}


def end_to_end(log: Path, out: Path, window: float, rate: float = 1.0) -> dict:
    """Publication of each row here -> `graphloc live` -> its poses read back here."""
    from cyclonedds.core import Listener
    from cyclonedds.sub import DataReader, InvalidSample
    from cyclonedds.topic import Topic

    from graphloc.manifest import read_manifest
    from benchmarks.live_publish import Publisher, log_messages
    from graphloc.live.ros2 import KEEP_POSES, POSE_TYPE, participant, qos
    from graphloc.live.ros2_types import dds_topic, idl_type

    names = [r.name for r in read_manifest(log).robots]
    dp = participant()
    received: dict = {}  # (robot, stamp ns) -> reception time

    def reader(robot):
        def on_data(rd):
            now = time.perf_counter()
            for s in rd.take(N=1024):
                if not isinstance(s, InvalidSample):
                    ns = s.header.stamp.sec * 1_000_000_000 + s.header.stamp.nanosec
                    received.setdefault((robot, ns), now)

        topic = Topic(dp, dds_topic(f"/{robot}/pose"), idl_type(POSE_TYPE))
        return DataReader(
            dp, topic, qos=qos(KEEP_POSES), listener=Listener(on_data_available=on_data)
        )

    readers = [reader(n) for n in names]  # noqa: F841 -- kept alive while the run goes
    messages = log_messages(log)
    published = np.zeros(len(messages))
    pub = Publisher(messages, dp)
    exe = Path(sys.executable).parent / "graphloc"
    argv = [exe, "live", "--ros2", "--manifest", log, "--out", out, "--publish"]
    argv += ["--window", str(window), "--idle", "3", "--no-progress"]
    live = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    alone = pub.wait_for_subscribers(300.0)
    if alone:
        live.kill()
        raise RuntimeError(f"graphloc live did not subscribe to {sorted(alone)}")

    def on_write(k, t):
        published[k] = t

    pub.run(rate, on_write=on_write)
    _, err = live.communicate(timeout=600)
    if live.returncode != 0:
        raise RuntimeError(f"graphloc live failed ({live.returncode}): {err[-2000:]}")
    time.sleep(0.5)  # the last poses on their way
    # publication time of each topic's k-th message; a ROS 2 line's `line` is k + 2
    by_topic: dict = {}
    for k, (_, topic, _, _) in enumerate(messages):
        by_topic.setdefault(topic, []).append(published[k])
    # per robot: its rows' times and publication times, in publication (= time) order
    rows_of: dict = {}
    for k, (t, topic, _, _) in enumerate(messages):
        rows_of.setdefault(topic.split("/")[3], []).append((t, published[k]))
    rows_of = {r: np.asarray(v) for r, v in rows_of.items()}
    way_in, update, way_out, total, age, missing = [], [], [], [], [], 0
    parts = {k: [] for k in ("queue", "before", "step", "step_cpu", "sinks", "later")}
    with open(out / "live_updates.csv", newline="") as fh:
        rows = [row for row in csv.DictReader(fh) if row["trigger_robot"]]  # not the final ones
    first = {}  # a trigger's push (its start time) -> its first step
    for row in rows:
        first.setdefault(row["pushed_s"], row["step"])
    for row in rows:
        topic = f"/graphloc/log/{row['trigger_robot']}/{row['trigger_table']}"
        sent = by_topic[topic][int(row["trigger_line"]) - 2]
        got = received.get((row["robot"], int(round(float(row["time"]) * 1e9))))
        if got is None:
            missing += 1
            continue
        arrived, written = float(row["arrived_s"]), float(row["ready_s"])
        way_in.append(arrived - sent)
        update.append(written - arrived)
        # the update's span: the row queued for the run loop, the work before the step
        # (the rows taken with it, its checks and graph building, and for a step after the
        # first one the trigger completed, the steps and sinks before it), the step
        # (iSAM2 update and covariances; wall and CPU) and the sinks (ready -> published)
        step = float(row["step_s"])
        parts["queue"].append(float(row["taken_s"]) - arrived)
        parts["before"].append(written - step - float(row["taken_s"]))
        parts["step"].append(step)
        parts["step_cpu"].append(float(row["step_cpu_s"]))
        parts["sinks"].append(float(row["sent_s"]) - written)
        if row["step"] != first[row["pushed_s"]]:
            parts["later"].append(written - arrived)
        way_out.append(got - written)
        total.append(got - sent)
        mine = rows_of[row["robot"]]  # the robot's newest row at the pose's time
        k = np.searchsorted(mine[:, 0], float(row["time"]), side="right") - 1
        if k >= 0:
            age.append(got - mine[k, 1])
    summary = json.loads((out / "live.json").read_text())
    return {
        "window_s": window,
        "rate": rate,
        "messages": len(messages),
        "poses": len(total),
        "poses_not_received": missing,
        "end_to_end_s": stats(total),
        "way_in_s": stats(way_in),
        "update_s": stats(update),
        "way_out_s": stats(way_out),
        "breakdown_s": {k: stats(v) for k, v in parts.items()},
        "age_s": stats(age),
        "skipped": summary["skipped"]["total"] + summary["skipped"]["team"]["total"],
        "skip_counts": {**summary["skipped"]["counts"], **summary["skipped"]["team"]["counts"]},
        "samples_s": [float(x) for x in total],
    }


def run(duration: float, out: Path, rate: float, windows=(0.0, 0.5)) -> dict:
    """The benchmark (module docstring); its working files under `out`."""
    from graphloc.datasets.mrclam import MRCLAM
    from graphloc.log_writer import write_planar_run

    from benchmarks.host import commit, machine

    load0 = os.getloadavg()
    base = write_planar_run(MRCLAM(DATASET6, duration=duration).load(), out / "dataset6")
    steps = []
    for size in TEAM_SIZES:
        log = team_log(base, out / f"team{size}", size)
        steps.append({"team": size, **step_latency(log)})
        print(f"team of {size}: {steps[-1]['latency_s']}", flush=True)
    e2e = []
    for w in windows:
        os.environ.update(lo_only_environment(150 + int(10 * w)))
        e2e.append(end_to_end(out / "team5", out / f"live_w{w:g}", w, rate))
        print(f"end to end, window {w:g} s: {e2e[-1]['end_to_end_s']}", flush=True)
    return {
        "dataset": "MRCLAM_Dataset6",
        "duration_s": duration,
        "target_p95_s": TARGET_P95_S,
        "steps": steps,
        "end_to_end": e2e,
        "machine": machine(),
        "commit": commit(),
        "load_average": {"before": list(load0), "after": list(os.getloadavg())},
    }


def plot(result: dict, path: Path) -> None:
    """Per-step latency by team size (p50, p95, max) and the end-to-end latencies' CDFs."""
    from graphloc.plots import plt  # the Agg backend, set there

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    sizes = [s["team"] for s in result["steps"]]
    for key, marker in (("p50", "o"), ("p95", "s"), ("max", "^")):
        a.plot(
            sizes, [1e3 * s["latency_s"][key] for s in result["steps"]], marker=marker, label=key
        )
    a.set(xlabel="robots", ylabel="per-step latency [ms]", xticks=sizes, yscale="log")
    a.set_title("live API update (iSAM2 + covariances)")
    a.legend()
    for e in result["end_to_end"]:
        x = np.sort(1e3 * np.asarray(e["samples_s"]))
        b.plot(x, np.arange(1, len(x) + 1) / len(x), label=f"window {e['window_s']:g} s")
    b.axvline(1e3 * result["target_p95_s"], color="k", ls="--", lw=0.8, label="20 ms")
    b.set(xlabel="row published -> pose received [ms]", ylabel="fraction of poses", xscale="log")
    b.set_title("end to end, Dataset6's five robots over ROS 2")
    b.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
