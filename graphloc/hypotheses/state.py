"""A HypothesisTracker's state as data: `save_state` writes the config and every track, commit
and log-odds as a versioned JSON file (`graphloc.session.write_data_file`, atomic; no pickle,
a loaded file never runs code); `load_state` reads it back, every field checked, ValueError
naming the file and the field."""

from __future__ import annotations

from dataclasses import asdict, fields

import gtsam
import numpy as np

from graphloc.factors.odometry import check_covariance
from graphloc.hypotheses.config import TrackerConfig
from graphloc.hypotheses.track import Track
from graphloc.session import read_data_file, write_data_file

SAVE_FORMAT = "graphloc-hypothesis-tracker"
SAVE_VERSION = 1
# the tracker's private attributes (without the leading "_") that make up its state
STATE_FIELDS = ("tracks", "next_id", "committed_id", "last_time", "logit", "max_gain")


def save_state(path, config: TrackerConfig, state: dict) -> None:
    """Write `config` and `state` (STATE_FIELDS -> value, as the tracker holds them) to `path`."""
    tracks = [
        {
            "mean": np.asarray(t.mean.matrix()).ravel().tolist(),
            "cov": t.cov.ravel().tolist(),
            "logw": t.logw,
            "id": t.track_id,
            "candidate": t.candidate,
            "misses": t.misses,
        }
        for t in state["tracks"]
    ]
    config = asdict(config)
    config["default_sigmas"] = list(config["default_sigmas"])
    payload = {
        "config": config,
        "tracks": tracks,
        "next_id": state["next_id"],
        "committed_id": state["committed_id"],
        "last_time": state["last_time"],
        "logit": [[i, v] for i, v in state["logit"].items()],
        "max_gain": [[i, v] for i, v in state["max_gain"].items()],
    }
    write_data_file(path, SAVE_FORMAT, SAVE_VERSION, payload, allow_nan=True)


def load_state(path) -> tuple[TrackerConfig, dict]:
    """The config and state `save_state` wrote. ValueError naming the file and the field."""
    raw = read_data_file(path, SAVE_FORMAT, SAVE_VERSION, "hypothesis tracker", allow_nan=True)
    try:
        return _parse(raw)
    except KeyError as exc:
        raise ValueError(f"{path}: missing field {exc}") from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: {exc}") from None


def _parse(raw: dict) -> tuple[TrackerConfig, dict]:
    def number(x, field, finite=True):
        ok = isinstance(x, (int, float)) and not isinstance(x, bool) and not np.isnan(x)
        if not ok or (finite and not np.isfinite(x)):
            kind = "finite number" if finite else "number"
            raise ValueError(f"{field}: expected a {kind}, got {x!r}")
        return float(x)

    def items(x, field, kind=list):
        if not isinstance(x, kind):
            raise ValueError(f"{field}: expected a {kind.__name__}, got {str(x)[:60]}")
        return x

    def integer(x, field):
        if isinstance(x, bool) or not isinstance(x, int):
            raise ValueError(f"{field}: expected an integer, got {x!r}")
        return x

    config = dict(items(raw["config"], "config", dict))
    if set(config) != {f.name for f in fields(TrackerConfig)}:
        raise ValueError(f"config: expected the fields of TrackerConfig, got {sorted(config)}")
    sigmas = items(config["default_sigmas"], "config.default_sigmas")
    config["default_sigmas"] = tuple(number(v, "config.default_sigmas") for v in sigmas)
    config = TrackerConfig(**config)  # each value of its field's type and rule (strict)
    tracks = []
    for k, t in enumerate(items(raw["tracks"], "tracks")):
        where = f"tracks[{k}]"
        items(t, where, dict)
        mean = np.array([number(v, f"{where}.mean") for v in items(t["mean"], f"{where}.mean")])
        cov = np.array([number(v, f"{where}.cov") for v in items(t["cov"], f"{where}.cov")])
        if mean.size != 16 or cov.size != 36:
            raise ValueError(
                f"{where}: mean needs 16 numbers and cov 36, got {mean.size}, {cov.size}"
            )
        T, cov = mean.reshape(4, 4), cov.reshape(6, 6)
        R = T[:3, :3]
        if not (np.abs(R @ R.T - np.eye(3)).max() < 1e-9 and np.linalg.det(R) > 0):
            raise ValueError(f"{where}.mean: not a rigid transform")
        check_covariance(cov, f"{where}.cov")
        pose = gtsam.Pose3(gtsam.Rot3(R), T[:3, 3])
        tracks.append(
            Track(
                pose,
                cov,
                number(t["logw"], f"{where}.logw", False),
                integer(t["id"], f"{where}.id"),
                integer(t["candidate"], f"{where}.candidate"),
                integer(t["misses"], f"{where}.misses"),
            )
        )
    state = {"tracks": tracks}
    state["next_id"] = integer(raw["next_id"], "next_id")
    committed = raw["committed_id"]
    state["committed_id"] = None if committed is None else integer(committed, "committed_id")
    last = raw["last_time"]
    state["last_time"] = None if last is None else number(last, "last_time")
    for name in ("logit", "max_gain"):
        pairs = items(raw[name], name)
        if not all(isinstance(p, list) and len(p) == 2 for p in pairs):
            raise ValueError(f"{name}: expected [track id, value] pairs")
        state[name] = {integer(i, f"{name} track id"): number(v, name, False) for i, v in pairs}
    return config, state
