"""`graphloc online RUN --out DIR`: iSAM2, one update per step, with `smooth`'s options and outputs
plus the causal estimate and latency.csv; `--checkpoint` / `--resume` (docs/outputs.md;
docs/design_core.md, "Online checkpoints")."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from graphloc import many_runs
from graphloc.checkpoint import read_checkpoint, write_checkpoint
from graphloc.commands import smooth

HELP = (
    "online iSAM2 smoothing of a multi-robot run frame by frame (latency, TUM, metrics JSON, PNGs)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    smooth.add_arguments(parser)
    parser.add_argument("--checkpoint", type=Path, help="write a checkpoint to this file")
    parser.add_argument(
        "--checkpoint-every", type=int, default=500, help="steps between checkpoints (default 500)"
    )
    parser.add_argument("--resume", type=Path, help="continue from this checkpoint")


def hooks(args: argparse.Namespace):
    """The checkpoint / resume callbacks `smooth.run_verb` hands to `solve`."""
    if args.checkpoint_every < 1:
        raise ValueError(f"--checkpoint-every must be >= 1, got {args.checkpoint_every}")
    if args.checkpoint_every > 10**9:
        raise ValueError(f"--checkpoint-every must be at most 1e9, got {args.checkpoint_every}")
    if args.checkpoint is None and args.resume is None:
        return None
    if args.resume is not None and not args.resume.is_file():
        raise ValueError(f"--resume {args.resume}: no such checkpoint file")
    folder = None if args.checkpoint is None else args.checkpoint.parent
    if folder is not None and (
        args.checkpoint.is_dir() or not folder.is_dir() or not os.access(folder, os.W_OK)
    ):
        raise ValueError(
            f"--checkpoint {args.checkpoint}: must be a file in a writable directory (checked "
            f"before the run is solved)"
        )

    def make(graph, values):
        done_before = read_checkpoint(args.resume, graph)["steps_done"] if args.resume else 0
        if args.resume is not None:
            print(
                f"resuming {args.resume}: replaying {done_before} of {len(graph.steps)} steps",
                flush=True,
            )
        if args.checkpoint is None:
            return {}

        def on_step(i):
            done = i + 1
            if done > done_before and done % args.checkpoint_every == 0:
                write_checkpoint(args.checkpoint, graph, done)

        def on_stop(done):
            if done >= done_before:  # stopped while replaying: the resumed file is further on
                write_checkpoint(args.checkpoint, graph, done)

        return {"on_step": on_step, "on_stop": on_stop}

    return make


def run(args: argparse.Namespace) -> int:
    make = hooks(args)
    return many_runs.dispatch(args, "online", smooth.run_verb, checkpoint=make)
