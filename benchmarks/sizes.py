"""Run sizes of every reproduction and benchmark, defined once: FULL (the papers' sizes) and
QUICK (CI: `scripts/reproduce.py TABLE --quick`, `scripts/make_results.py --quick`, the
scripts' --quick)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class RunSizes:
    """table1_trials: seed 000 Table I trials (paper: 1000); table2_samples: trials timed one
    by one for Table II; table3_runs: seed 000 Table III runs per cell (paper: 100);
    seed004_runs x seed004_frames: seed 004 Table 1 tracks per cell (paper: 1000 runs);
    seed001_frames1 / seed001_frames2: frames of seed 001 experiment 1's two runs;
    hypotheses_runs: runs per cell of scripts/bench_hypotheses.py (the Table III setup with
    every method's statistics); latency_frames: updates of its long latency run."""

    table1_trials: int
    table2_samples: int
    table3_runs: int
    seed004_runs: int
    seed004_frames: int
    seed001_frames1: int
    seed001_frames2: int
    hypotheses_runs: int
    latency_frames: int


FULL = RunSizes(
    table1_trials=1000,
    table2_samples=100,
    table3_runs=100,
    seed004_runs=1000,
    seed004_frames=10,
    seed001_frames1=300,
    seed001_frames2=200,
    hypotheses_runs=100,
    latency_frames=10000,
)
QUICK = RunSizes(
    table1_trials=100,
    table2_samples=100,
    table3_runs=5,
    seed004_runs=50,
    seed004_frames=10,
    seed001_frames1=60,
    seed001_frames2=40,
    hypotheses_runs=10,
    latency_frames=2000,
)


def run_sizes(quick: bool) -> RunSizes:
    return QUICK if quick else FULL
