"""The event-clocked scenarios through `graphloc smooth` / `online`'s route (`run_team`), per
seed: each robot's ATE RMSE (batch; online final and causal) and the candidate-set decisions
metrics.json holds, written as JSON -- the before / after table of a change to the event route
(`graphloc.live.events`). Usage:

    .venv/bin/python scripts/bench_event_runs.py --seeds 1-5 --json out.json
    .venv/bin/python scripts/bench_event_runs.py --compare before.json after.json
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

SCENARIOS = ("kaushik-p3p-error", "breitenmoser-target", "feng-probabilistic")


def measure(name: str, seed: int, root: Path) -> dict:
    """One scenario seed: simulated, then batch and online through `run_team`."""
    from graphloc.datasets.scenarios import generate
    from graphloc.runner.team_run import run_team

    source = root / f"{name}-{seed}"
    generate(name, source, seed)
    row = {"scenario": name, "seed": seed}
    for mode in ("batch", "online"):
        cpu = time.process_time()
        outcome = run_team(source, root / f"{name}-{seed}-{mode}", mode)
        m = outcome.metrics
        row[f"{mode}_cpu_s"] = time.process_time() - cpu
        row[f"{mode}_hypotheses"] = outcome.result.hypotheses
        for robot, per in m["per_robot"].items():
            for key in ("batch", "online", "online_causal"):
                if key in per:
                    row[f"{robot}_{key}_ate"] = per[key]["ate_rmse"]
        d = m["decisions"]
        row[f"{mode}_committed"] = d["committed"]
        row[f"{mode}_wrong"] = d["wrong"]
        row[f"{mode}_sets"] = d["candidate_sets"]
        row[f"{mode}_consistent"] = m["consistent"]
    return row


def compare(before: list, after: list) -> None:
    """The rows of two runs side by side: every numeric field that differs."""
    keyed = {(r["scenario"], r["seed"]): r for r in before}
    for r in after:
        b = keyed.get((r["scenario"], r["seed"]), {})
        diffs = [
            f"{k} {b.get(k)!s:.8} -> {v!s:.8}"
            for k, v in r.items()
            if "cpu" not in k and b.get(k) != v
        ]
        print(f"{r['scenario']} {r['seed']}: " + ("; ".join(diffs) if diffs else "same"))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1-5", help="first-last")
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--json", type=Path, help="write the rows here")
    parser.add_argument("--compare", nargs=2, type=Path, metavar=("BEFORE", "AFTER"))
    args = parser.parse_args(argv)
    if args.compare:
        compare(*(json.loads(p.read_text()) for p in args.compare))
        return 0
    first, _, last = args.seeds.partition("-")
    seeds = range(int(first), int(last or first) + 1)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenarios.split(","):
            for seed in seeds:
                rows.append(measure(name, seed, Path(tmp)))
                print(json.dumps(rows[-1]), flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
