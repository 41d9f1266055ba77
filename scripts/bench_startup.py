"""The front door's timings (issue 47), measured on the command line as a user meets it:

- start-up: wall time and peak RSS of `graphloc --version` and of `graphloc VERB --help` for
  every verb of `graphloc.cli.VERBS`, each run `--repeats` times (median and max);
- Ctrl-C: SIGINT sent at seeded random moments of `graphloc online` / `graphloc smooth` on a
  simulated run (`feng-probabilistic`) and on MRCLAM Dataset6; the time from the signal to the
  process's exit, its exit code, whether stderr holds a traceback, the line it ended with and,
  when it wrote metrics.json, whether that says `"partial": true` (each verb is first run
  uninterrupted once: its wall time sets the moments, fractions of it);
- the demo: wall time of `graphloc demo` (`make demo`'s run) `--demo-repeats` times.

`--peer-commit REV` measures a peer in the same run, interleaved with graphloc run by run: the
source tree of REV (`git archive`, with factors/ and datasets/ linked in as graphloc.factors /
graphloc.datasets) run by this interpreter (`python -m graphloc`, PYTHONPATH), so that both
see the same load; its start-up (and with `--peer-sigint` its Ctrl-C) rows stand beside
graphloc's with their ratio. Every child is a fresh process (`--graphloc`, default the
`graphloc` beside this interpreter) run in a folder outside the checkout; peak RSS from
`os.wait4`. The machine (CPU, cores, load average before and after) is recorded with the
numbers. Writes JSON (`--json`) and renders markdown (`--md`) from it
(benchmarks.render.startup; `scripts/render_docs.py results_startup.md` re-renders the doc
from the committed JSON).

    .venv/bin/python scripts/bench_startup.py --peer-commit baba18c \\
        --json docs/results_startup.json --md docs/results_startup.md

A measurement, not a test: the targets (start-up under 0.3 s, Ctrl-C back within 2 s) are
read off the table, never asserted here."""

from __future__ import annotations

import argparse
import json
import os
import random
import shlex
import signal
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/
from benchmarks.host import commit, machine  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MRCLAM = ROOT.parent / "shared" / "data" / "mrclam" / "MRCLAM_Dataset6"
SCENARIO = "feng-probabilistic"
TIMEOUT = 900.0  # [s] a child still running this long after its signal is killed (and said so)


def _graphloc_default() -> str:
    return str(Path(sys.executable).parent / "graphloc")


def _reap(proc: subprocess.Popen, block: bool) -> tuple[int, float] | None:
    """(exit code, peak RSS [MB]) of `proc` once it has exited (None while it runs, unless
    `block`)."""
    pid, status, usage = os.wait4(proc.pid, 0 if block else os.WNOHANG)
    if not pid:
        return None
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, usage.ru_maxrss / 1024.0


def _wait(proc: subprocess.Popen, timeout: float) -> tuple[int, float]:
    """(exit code, peak RSS [MB]) of `proc`, killed after `timeout` s (code -9 then)."""
    deadline = time.monotonic() + timeout
    while (done := _reap(proc, block=False)) is None:
        if time.monotonic() > deadline:
            proc.kill()
            return _reap(proc, block=True)
        time.sleep(0.005)
    return done


def _stats(values: list[float]) -> dict:
    return {"median": statistics.median(values), "max": max(values), "n": len(values)}


def _once(cmd: list[str], cwd: Path, env: dict | None) -> tuple[float, float, int]:
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        cmd, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    code, peak = _wait(proc, 120.0)
    return time.perf_counter() - t0, peak, code


def startup(commands: dict, verbs: list[str], repeats: int, cwd: Path) -> list[dict]:
    """Wall time and peak RSS of `--version` and of `VERB --help` for every verb, for each
    command of `commands` (name -> (argv prefix, env)), interleaved run by run."""
    rows = []
    for extra in [["--version"]] + [[v, "--help"] for v in verbs]:
        runs = {name: ([], [], set()) for name in commands}
        for _ in range(repeats):
            for name, (cmd, env) in commands.items():
                wall, peak, code = _once([*cmd, *extra], cwd, env)
                runs[name][0].append(wall)
                runs[name][1].append(peak)
                runs[name][2].add(code)
        row = {"command": "graphloc " + " ".join(extra)}
        for name, (walls, rss, codes) in runs.items():
            row[name] = {
                "wall_s": _stats(walls),
                "peak_rss_mb": _stats(rss),
                "exit_codes": sorted(codes),
            }
        rows.append(row)
        shown = ", ".join(f"{n} {statistics.median(r[0]):.3f} s" for n, r in runs.items())
        print(f"  {row['command']}: {shown}", file=sys.stderr)
    return rows


def _uninterrupted(cmd: list[str], cwd: Path, env: dict | None) -> tuple[float, int]:
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        cmd, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    code, _ = _wait(proc, 3600.0)
    return time.perf_counter() - t0, code


def interrupt(cmd: list[str], at_s: float, out: Path, cwd: Path, env: dict | None = None) -> dict:
    """Run `cmd`, send SIGINT `at_s` seconds after its start, wait for the exit."""
    with tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=err)
        sent, done = None, None
        while (done := _reap(proc, block=False)) is None and time.perf_counter() - t0 < at_s:
            time.sleep(0.005)
        if done is None:
            proc.send_signal(signal.SIGINT)
            sent = time.perf_counter()
            done = _wait(proc, TIMEOUT)
        code = done[0]
        end = time.perf_counter()
        err.seek(0)
        text = err.read().decode("utf-8", "replace")
    lines = [ln.strip() for ln in text.replace("\r", "\n").splitlines() if ln.strip()]
    lines = [ln for ln in lines if not ln.startswith("graphloc: ")]  # -v log lines
    metrics = out / "metrics.json"
    partial = json.loads(metrics.read_text()).get("partial") if metrics.is_file() else None
    return {
        "at_s": round(at_s, 3),
        "signalled": sent is not None,
        "exit_s": None if sent is None else end - sent,
        "exit_code": code,
        "traceback": "Traceback (most recent call last)" in text,
        "said": [ln for ln in lines if "SIGINT" in ln or "interrupt" in ln.lower()][-2:],
        "metrics_partial": partial,
    }


def sigint(
    name: str, command: tuple, verb: str, run: Path, moments: int, seed: int, work: Path
) -> dict:
    """SIGINT at `moments` seeded random fractions of the verb's uninterrupted wall time."""
    cmd, env = command
    base = [*cmd, verb, str(run), "--no-progress"]
    full, code = _uninterrupted([*base, "--out", str(work / f"{name}_{verb}_full")], work, env)
    rng = random.Random(f"{seed}:{verb}:{run.name}")
    fractions = sorted(rng.uniform(0.02, 0.98) for _ in range(moments))
    trials = []
    for n, f in enumerate(fractions):
        out = work / f"{name}_{verb}_{run.name}_{n}"
        trials.append(interrupt([*base, "--out", str(out)], max(0.3, f * full), out, work, env))
        t = trials[-1]
        after = "-" if t["exit_s"] is None else f"{t['exit_s']:.2f}"
        print(
            f"  {name} {verb} {run.name}: SIGINT at {t['at_s']:.1f} s -> exit "
            f"{t['exit_code']} after {after} s",
            file=sys.stderr,
        )
    delays = [t["exit_s"] for t in trials if t["exit_s"] is not None]
    return {
        "command": name,
        "verb": verb,
        "run": run.name,
        "uninterrupted_s": full,
        "uninterrupted_exit_code": code,
        "trials": trials,
        "exit_s": _stats(delays) if delays else None,
    }


def demo(command: tuple, repeats: int, work: Path) -> dict:
    cmd, env = command
    walls, codes = [], set()
    for n in range(repeats):
        wall, code = _uninterrupted(
            [*cmd, "demo", "--out", str(work / f"demo{n}"), "--no-progress"], work, env
        )
        walls.append(wall)
        codes.add(code)
        print(f"  graphloc demo: {wall:.1f} s (exit {code})", file=sys.stderr)
    return {
        "command": "graphloc demo --out DIR",
        "wall_s": _stats(walls),
        "walls": walls,
        "exit_codes": sorted(codes),
    }


def peer_tree(rev: str, into: Path) -> Path:
    """The source tree of commit `rev` under `into`, importable as graphloc with PYTHONPATH
    (factors/ and datasets/ linked in as graphloc.factors / graphloc.datasets)."""
    archive = into / "peer.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(archive), rev], check=True)
    tree = into / "peer"
    tree.mkdir()
    with tarfile.open(archive) as tar:
        tar.extractall(tree, filter="data")
    for folder in ("factors", "datasets"):
        (tree / "graphloc" / folder).symlink_to(tree / folder, target_is_directory=True)
    return tree


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--graphloc", default=_graphloc_default(), help="the command to time")
    p.add_argument("--peer-commit", help="also time this commit's tree, interleaved (a peer)")
    p.add_argument("--peer-sigint", action="store_true", help="the peer's Ctrl-C too (slow)")
    p.add_argument("--repeats", type=int, default=10, help="runs per start-up command")
    p.add_argument("--moments", type=int, default=5, help="SIGINT trials per verb and run")
    p.add_argument("--seed", type=int, default=0, help="seed of the SIGINT moments")
    p.add_argument("--mrclam", type=Path, default=MRCLAM, help="MRCLAM Dataset6 directory")
    p.add_argument("--demo-repeats", type=int, default=3, help="runs of graphloc demo (0: none)")
    p.add_argument("--skip", nargs="*", default=[], choices=["startup", "sigint", "mrclam", "demo"])
    p.add_argument("--json", type=Path, default=ROOT / "docs" / "results_startup.json")
    p.add_argument("--md", type=Path, default=ROOT / "docs" / "results_startup.md")
    args = p.parse_args(argv)
    from graphloc import __version__
    from graphloc.cli import VERBS

    shown = list(argv if argv is not None else sys.argv[1:])
    result: dict = {
        "command": " ".join(["python scripts/bench_startup.py", *map(shlex.quote, shown)]),
        "graphloc_version": __version__,
        "commit": commit(),
        "graphloc": shlex.split(args.graphloc),
        "peer": None,
        "machine": machine(),
        "load_average": {"before": list(os.getloadavg())},
        "repeats": args.repeats,
    }
    with tempfile.TemporaryDirectory(prefix="bench_startup_") as tmp:
        work = Path(tmp)  # every child runs here, outside the checkout
        commands = {"graphloc": (shlex.split(args.graphloc), None)}
        if args.peer_commit:
            tree = peer_tree(args.peer_commit, work)
            env = {**os.environ, "PYTHONPATH": str(tree)}
            commands["peer"] = ([sys.executable, "-m", "graphloc"], env)
            result["peer"] = f"commit {args.peer_commit} (python -m graphloc from its tree)"
        if "startup" not in args.skip:
            print("start-up:", file=sys.stderr)
            result["startup"] = startup(commands, list(VERBS), args.repeats, work)
        if "sigint" not in args.skip:
            print("SIGINT:", file=sys.stderr)
            sim = work / "sim_run"
            subprocess.run(
                [*commands["graphloc"][0], "simulate", SCENARIO, "--out", str(sim), "-q"],
                cwd=work,
                check=True,
            )
            runs = [sim] + ([args.mrclam] if "mrclam" not in args.skip else [])
            timed = {k: v for k, v in commands.items() if k == "graphloc" or args.peer_sigint}
            result["sigint"] = [
                sigint(name, command, verb, run, args.moments, args.seed, work)
                for run in runs
                for verb in ("smooth", "online")
                for name, command in timed.items()
            ]
        if "demo" not in args.skip and args.demo_repeats > 0:
            print("demo:", file=sys.stderr)
            result["demo"] = demo(commands["graphloc"], args.demo_repeats, work)
    result["load_average"]["after"] = list(os.getloadavg())
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=1) + "\n")
    sys.path.insert(0, str(ROOT))  # the checkout: benchmarks/ (not installed)
    from benchmarks.render import render

    args.md.write_text(render("startup", json.loads(args.json.read_text())))
    print(f"wrote {args.json} and {args.md}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
