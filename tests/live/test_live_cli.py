"""`graphloc live` (issue 50) on a log directory: tailed while a logger writes it, the outputs
are `graphloc online`'s on the finished log; Ctrl-C ends it cleanly with its outputs written."""

from __future__ import annotations

import csv
import heapq
import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from graphloc.cli import main
from graphloc.manifest import MANIFEST, read_manifest


def _write_slowly(src: Path, dst: Path, pause: float = 0.002) -> None:
    """A logger: the landmark map and the manifest, then every table's lines in time order
    across tables (each line in two writes, so the tail meets partial lines), TUM ground truth
    at the end."""
    time.sleep(0.3)  # the verb waits for the manifest
    for extra in src.glob("*.csv"):  # landmarks.csv: the map, known before the run
        (dst / extra.name).write_bytes(extra.read_bytes())
    (dst / MANIFEST).write_bytes((src / MANIFEST).read_bytes())
    manifest = read_manifest(src)
    streams = []
    for r in manifest.robots:
        for table, rel in r.tables.items():
            (dst / rel).parent.mkdir(parents=True, exist_ok=True)
            lines = (src / rel).read_text().splitlines(keepends=True)
            if rel.endswith(".tum"):
                continue
            (dst / rel).write_text(lines[0])
            streams.append([(float(x.split(",")[0]), rel, x) for x in lines[1:]])
    for k, (_, rel, line) in enumerate(heapq.merge(*streams)):
        with open(dst / rel, "a") as fh:
            fh.write(line[:5])
            fh.flush()
            fh.write(line[5:])
        if k % 10 == 0:
            time.sleep(pause)
    for r in manifest.robots:  # ground truth last: read when the run ends
        for rel in r.tables.values():
            if rel.endswith(".tum"):
                (dst / rel).write_bytes((src / rel).read_bytes())


def _tums(out: Path) -> dict:
    return {p.name: np.loadtxt(p, ndmin=2) for p in sorted(out.glob("*_online.tum"))}


def test_live_on_a_log_being_written_is_graphloc_online(planar_log, tmp_path):
    live = tmp_path / "live"
    live.mkdir()
    logger = threading.Thread(target=_write_slowly, args=(planar_log, live))
    logger.start()
    out = tmp_path / "out"
    argv = ["live", "--log-dir", str(live), "--out", str(out), "--idle", "1.5", "--no-progress"]
    assert main(argv) == 0
    logger.join()
    assert (
        main(["online", str(planar_log), "--out", str(tmp_path / "online"), "--no-progress"]) == 0
    )
    want, got = _tums(tmp_path / "online"), _tums(out)
    assert want and got.keys() == want.keys()
    for name in want:
        assert got[name].shape == want[name].shape
        assert np.abs(got[name] - want[name]).max() < 1e-9, name
    summary = json.loads((out / "live.json").read_text())
    assert summary["ended"] == "idle" and summary["skipped"]["total"] == 0
    lines: dict = {}  # every data line of every table arrived once
    for r in read_manifest(planar_log).robots:
        for table, rel in r.tables.items():
            n = len((planar_log / rel).read_text().splitlines()) - 1
            lines[table] = lines.get(table, 0) + n
    assert summary["rows"] == lines
    # live_updates.csv: per pose, the trigger's way through the process in order (arrived,
    # taken by the run loop, push began, step began, poses ready, sinks done)
    with open(out / "live_updates.csv", newline="") as fh:
        updates = [row for row in csv.DictReader(fh) if row["trigger_robot"]]
    assert updates
    for row in updates:
        t = {k: float(row[k]) for k in ("arrived_s", "taken_s", "pushed_s", "ready_s", "sent_s")}
        began = t["ready_s"] - float(row["step_s"])
        assert t["arrived_s"] <= t["taken_s"] <= t["pushed_s"] <= began + 1e-6
        assert began < t["ready_s"] <= t["sent_s"] and float(row["step_cpu_s"]) >= 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["partial"] is False
    # the ground truth, written last, was read at the end: the estimates were evaluated
    assert any(v.get("online") for v in metrics["per_robot"].values())


def test_ctrl_c_ends_live_cleanly(planar_log, tmp_path):
    """SIGINT while live: the loop stops, the rows in are solved and online's outputs written,
    exit 0; live.json says it was stopped."""
    out = tmp_path / "out"
    exe = Path(sys.executable).parent / "graphloc"
    proc = subprocess.Popen(
        [exe, "live", "--log-dir", planar_log, "--out", out, "--view", "0", "--no-progress"],
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    line = proc.stderr.readline()  # said once the team is open and the view serves
    assert "Foxglove view on ws://127.0.0.1:" in line, line
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    assert "Traceback" not in stderr
    assert json.loads((out / "live.json").read_text())["ended"] == "stopped"
    assert _tums(out) and (out / "metrics.json").is_file()


def test_killed_and_restarted_from_its_checkpoint_loses_nothing(planar_log, tmp_path, capsys):
    """`graphloc live --checkpoint` killed (SIGKILL) while the logger has written half the
    rows, then restarted with the same checkpoint once the log is complete: the team resumes
    from the checkpoint, the tail skips the rows it holds and pushes the others, and the
    outputs are `graphloc online`'s on the whole log."""
    live, ck = tmp_path / "live", tmp_path / "live.ckpt"
    live.mkdir()
    for extra in planar_log.glob("*.csv"):
        (live / extra.name).write_bytes(extra.read_bytes())
    (live / MANIFEST).write_bytes((planar_log / MANIFEST).read_bytes())
    manifest = read_manifest(planar_log)
    halves = {}
    for r in manifest.robots:
        for rel in r.tables.values():
            lines = (planar_log / rel).read_text().splitlines(keepends=True)
            (live / rel).parent.mkdir(parents=True, exist_ok=True)
            cut = 1 + (len(lines) - 1) // 2
            (live / rel).write_text("".join(lines[:cut]))
            halves[rel] = "".join(lines[cut:])
    exe = Path(sys.executable).parent / "graphloc"
    argv = [exe, "live", "--log-dir", live, "--checkpoint", ck, "--checkpoint-every", "3"]
    proc = subprocess.Popen(argv + ["--out", tmp_path / "o1", "--no-progress"])
    end = time.monotonic() + 120
    while not ck.exists() and time.monotonic() < end:
        time.sleep(0.1)
    assert ck.exists()
    time.sleep(0.5)
    proc.kill()
    proc.wait(timeout=30)
    for rel, rest in halves.items():
        with open(live / rel, "a") as fh:
            fh.write(rest)
    out = tmp_path / "o2"
    argv = ["live", "--log-dir", str(live), "--checkpoint", str(ck), "--checkpoint-every", "3"]
    assert main(argv + ["--out", str(out), "--idle", "1.5", "--no-progress"]) == 0
    assert (
        main(["online", str(planar_log), "--out", str(tmp_path / "online"), "--no-progress"]) == 0
    )
    want, got = _tums(tmp_path / "online"), _tums(out)
    assert want and got.keys() == want.keys()
    for name in want:
        assert got[name].shape == want[name].shape
        assert np.abs(got[name] - want[name]).max() < 1e-9, name


def test_live_on_a_finished_kaushik_log_is_graphloc_online(tmp_path):
    """kaushik-p3p-error, whose marker stream is never decided: `graphloc live --log-dir` on
    the finished log places the camera where `graphloc online` does (the event route's one
    rule, `graphloc.live.events`) and writes the same estimates."""
    from graphloc.datasets.scenarios import generate

    log = tmp_path / "log"
    generate("kaushik-p3p-error", log, 2)
    out = tmp_path / "live"
    argv = ["live", "--log-dir", str(log), "--out", str(out), "--idle", "1.0", "--no-progress"]
    assert main(argv) == 0
    assert main(["online", str(log), "--out", str(tmp_path / "online"), "--no-progress"]) == 0
    want, got = _tums(tmp_path / "online"), _tums(out)
    assert "climber_online.tum" in want and got.keys() == want.keys()
    for name in want:
        assert got[name].shape == want[name].shape
        assert np.abs(got[name] - want[name]).max() < 1e-9, name
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["per_robot"]["climber"]["online"]["ate_rmse"] < 0.1
    assert "unanchored_robot" not in metrics["skipped"]["counts"]
