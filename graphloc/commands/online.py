"""`graphloc online RUN --out DIR`: online smoothing with iSAM2, one incremental update per
frame, per-frame latency recorded; same factors, options and outputs as `graphloc smooth`, plus
the causal (as-it-happened) estimate's metrics and latency plot."""

from __future__ import annotations

import argparse

from graphloc.commands import smooth

HELP = "online iSAM2 smoothing of a multi-robot run frame by frame (latency, TUM, metrics JSON, PNGs)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    smooth.add_arguments(parser)


def run(args: argparse.Namespace) -> int:
    return smooth.run_verb(args, "online")
