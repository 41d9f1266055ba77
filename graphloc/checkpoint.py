"""The online checkpoint file ("graphloc-online-checkpoint"): steps done and the graph's
fingerprint, written by `graphloc online --checkpoint` and by a live team."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from pathlib import Path

CHECKPOINT_FORMAT = "graphloc-online-checkpoint"
CHECKPOINT_VERSION = 1


def fingerprint(graph) -> str:
    """SHA-256 of what makes two graphs the same sequence of updates: the run's name, the
    effective configuration, every step's time and factor count."""
    body = json.dumps(  # a hash: the encoding of earlier checkpoints
        {
            "run": graph.run.name,
            "config": asdict(graph.config),
            "steps": [[t, len(group)] for t, group in graph.steps],
        },
        default=str,
        sort_keys=True,
    )
    return hashlib.sha256(body.encode()).hexdigest()


def write_checkpoint(path: Path, graph, steps_done: int, extra: dict | None = None) -> None:
    """The checkpoint of `graph` after `steps_done` steps (`extra`: more payload keys, e.g. a
    live team's rows)."""
    from graphloc.datafile import write_data_file

    write_data_file(
        path,
        CHECKPOINT_FORMAT,
        CHECKPOINT_VERSION,
        {
            "run": graph.run.name,
            "fingerprint": fingerprint(graph),
            "steps_done": int(steps_done),
            "steps_total": len(graph.steps),
            **(extra or {}),
        },
        allow_nan=extra is not None,
    )


def read_checkpoint(path: Path, graph, allow_nan: bool = False) -> dict:
    """The checkpoint's payload after checking it belongs to `graph` (ValueError otherwise)."""
    data = read_checkpoint_file(path, allow_nan)
    done = data.get("steps_done")
    if data.get("fingerprint") != fingerprint(graph):
        raise ValueError(
            f"{path}: the checkpoint is of another run or configuration (run "
            f"{data.get('run')!r}); resume with the same RUN and options"
        )
    if not (type(done) is int and 0 <= done <= len(graph.steps)):  # true is no step count
        raise ValueError(
            f"{path}: field 'steps_done' must be an integer in [0, {len(graph.steps)}], got "
            f"{done!r}"
        )
    return data


def read_checkpoint_file(path: Path, allow_nan: bool = False) -> dict:
    """A checkpoint file's payload, its format and integrity checked (ValueError naming it)."""
    from graphloc.datafile import read_data_file

    return read_data_file(
        path, CHECKPOINT_FORMAT, CHECKPOINT_VERSION, "online checkpoint", allow_nan=allow_nan
    )
