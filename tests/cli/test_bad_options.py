"""Issue 47, the battery of bad options: every numeric option of every verb -- the fields of the
verb's config dataclass on the command line, the nested fields of its `--config FILE.toml`
tables, and the verbs' own numeric flags -- given NaN, inf, a value beyond any sane bound, a
fraction for an integer or text for a number. Each is one `error:` line naming the option (and,
from a config file, the file and line), exit code 2, before any work: the per-test timeouts
bound each case, so a value that is accepted and starts a huge simulation or solve fails.
"""

from __future__ import annotations

import dataclasses
import re
import typing

import pytest

from graphloc import exitcodes
from graphloc.config import option_fields
from graphloc.datasets import scenario_names
from graphloc.datasets.scenarios import scenario_config_class
from graphloc.pipelines.map_fusion.options import FuseMapsOptions
from graphloc.pipelines.team_graph.options import RunOptions

HUGE_INT = str(10**29)
FLOAT_VALUES = ["nan", "-inf", "1e308", "abc"]
INT_VALUES = ["-" + HUGE_INT, "1.5", "abc"]


def _verbs():
    """(verb command prefix, config class, fields excluded from its options)."""
    from graphloc.commands.demo import USER_INPUTS
    from graphloc.commands.validate import SKIPPED

    out = [
        (["validate", "{log}"], RunOptions, SKIPPED),
        (["smooth", "{log}", "--out", "{out}"], RunOptions, ()),
        (["online", "{log}", "--out", "{out}"], RunOptions, ()),
        (["fuse-maps", "--simulate", "dual-robot-room", "--out", "{out}"], FuseMapsOptions, ()),
        (["demo", "--out", "{out}"], FuseMapsOptions, USER_INPUTS),
    ]
    for name in scenario_names():
        out.append((["simulate", name, "--out", "{out}"], scenario_config_class(name), ("seed",)))
    return out


def _numeric(config_class, exclude=()) -> dict:
    return {
        name: kind
        for name, kind in option_fields(config_class, exclude).items()
        if kind in (int, float)
    }


def _cli_cases():
    cases = []
    for prefix, cls, exclude in _verbs():
        for name, kind in _numeric(cls, exclude).items():
            for value in FLOAT_VALUES if kind is float else INT_VALUES:
                flag = "--" + name.replace("_", "-")
                label = f"{' '.join(prefix[:2] if prefix[0] == 'simulate' else prefix[:1])}"
                cases.append(pytest.param(prefix, flag, value, name, id=f"{label}{flag}={value}"))
    # the verbs' own numeric flags
    cases += [
        pytest.param(
            ["online", "{log}", "--out", "{out}"],
            "--checkpoint-every",
            v,
            "checkpoint",
            id=f"online--checkpoint-every={v}",
        )
        for v in ("0", "-1", HUGE_INT, "1.5", "nan")
    ]
    cases += [
        pytest.param(
            ["smooth", "{log}", "{log}", "--out", "{out}"],
            "--workers",
            v,
            "workers",
            id=f"smooth--workers={v}",
        )
        for v in ("0", "-1", HUGE_INT, "1.5")
    ]
    cases += [
        pytest.param(
            ["simulate", "dual-robot-room", "--out", "{out}"],
            "--seed",
            v,
            "seed",
            id=f"simulate--seed={v}",
        )
        for v in ("-1", HUGE_INT, "1.5")
    ]
    return cases


def _expand(argv, log, out):
    return [str(a).format(log=log, out=out) for a in argv]


def _named(text: str, name: str) -> bool:
    pattern = re.escape(name).replace(r"\_", "[-_. ]").replace("_", "[-_. ]")
    return re.search(pattern, text, re.I) is not None


@pytest.mark.timeout(20)
@pytest.mark.parametrize("prefix, flag, value, name", _cli_cases())
def test_a_bad_option_value_is_one_error_naming_the_option(
    planar_log_template, cli, tmp_path, prefix, flag, value, name
):
    planar_log = planar_log_template  # read only
    out = tmp_path / "out"
    got = cli([*_expand(prefix, planar_log, out), f"{flag}={value}"], out=out)
    assert got.code == exitcodes.BAD_INPUT, (got.code, got.err[-1500:])
    assert _named(got.err, name), got.err
    assert not (out / "metrics.json").exists() and not (out / "fusion_report.json").exists()


# ---- the same through --config: every field, nested tables included ---------------------------
def _fields(cls, prefix=()):
    """(dotted path, kind) of every scalar numeric field of `cls` and its nested configs."""
    hints = typing.get_type_hints(cls)
    default = cls()
    for f in dataclasses.fields(cls):
        value = getattr(default, f.name)
        if dataclasses.is_dataclass(value):
            yield from _fields(type(value), (*prefix, f.name))
            continue
        hint = hints.get(f.name)
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        kind = args[0] if len(args) == 1 else hint
        if kind in (int, float) and f.init:
            yield (*prefix, f.name), kind


def _toml_cases():
    cases = []
    seen = set()
    for prefix, cls, exclude in _verbs():
        if cls in seen:
            continue
        seen.add(cls)
        for path, kind in _fields(cls):
            if path[-1] in exclude:
                continue
            for value in ("nan", "-1e308") if kind is float else (HUGE_INT, '"x"'):
                table = ".".join(path[:-1])
                label = cls.__name__ + "." + ".".join(path)
                cases.append(pytest.param(prefix, table, path[-1], value, id=f"{label}={value}"))
    return cases


@pytest.mark.timeout(20)
@pytest.mark.parametrize("prefix, table, key, value", _toml_cases())
def test_a_bad_config_file_value_names_the_file_line_and_field(
    planar_log_template, cli, tmp_path, prefix, table, key, value
):
    planar_log = planar_log_template  # read only
    out = tmp_path / "out"
    config = tmp_path / "in" / "bad.toml"
    config.parent.mkdir(exist_ok=True)
    head = f"# a config\n[{table}]\n" if table else "# a config\n"
    config.write_text(f"{head}{key} = {value}\n")
    line = 3 if table else 2
    got = cli([*_expand(prefix, planar_log, out), "--config", config], out=out)
    assert got.code == exitcodes.BAD_INPUT, (got.code, got.err[-1500:])
    assert re.search(rf"bad\.toml: line {line}: ", got.error_line), got.error_line
    assert _named(got.error_line, key), got.error_line


# ---- sizes that would allocate or run for ever: a range error at once --------------------------
SIZE_CASES = [
    (["simulate", "dual-robot-room", "--out", "{out}", "--frames", "1000000000"], "frames"),
    (["simulate", "kaushik-p3p-error", "--out", "{out}", "--runs", "1000000000"], "runs"),
    (["simulate", "kaushik-p3p-error", "--out", "{out}", "--frames", "1000000000"], "frames"),
    (["simulate", "crawler-pair", "--out", "{out}", "--width", "1000000000"], "width"),
    (["simulate", "crawler-pair", "--out", "{out}", "--supersample", "100000"], "supersample"),
    (["simulate", "breitenmoser-target", "--out", "{out}", "--frames", "1000000000"], "frames"),
    (["simulate", "feng-deterministic", "--out", "{out}", "--trials", "1000000000"], "trials"),
    (["simulate", "feng-probabilistic", "--out", "{out}", "--rate-hz", "1e9"], "rate_hz"),
    (["simulate", "feng-probabilistic", "--out", "{out}", "--max-time", "1e9"], "max_time"),
    (
        ["fuse-maps", "--simulate", "dual-robot-room", "--out", "{out}", "--frames", "1000000000"],
        "frames",
    ),
    (["smooth", "{log}", "--out", "{out}", "--keyframe-dt", "1e-9"], "keyframe_dt"),
    (["smooth", "{log}", "--out", "{out}", "--keyframe-dt", "1e300"], "keyframe_dt"),
    (["smooth", "{log}", "--out", "{out}", "--sync-tolerance", "1e300"], "sync_tolerance"),
    (["validate", "{log}", "--duration", "1e300"], "duration"),
]


@pytest.mark.timeout(20)
@pytest.mark.parametrize(
    "argv, name", SIZE_CASES, ids=[" ".join(c[0][:2] + c[0][-2:]) for c in SIZE_CASES]
)
def test_a_size_beyond_its_bound_is_a_range_error_at_once(
    planar_log_template, cli, tmp_path, argv, name
):
    planar_log = planar_log_template  # read only
    out = tmp_path / "out"
    got = cli(_expand(argv, planar_log, out), out=out)
    assert got.code == exitcodes.BAD_INPUT, (got.code, got.err[-1500:])
    assert _named(got.error_line, name) and re.search(r"must be|within|at most", got.error_line)


def test_a_config_file_range_error_names_file_and_line(planar_log, cli, tmp_path):
    """The issue's cases: keyframe_dt = 1e308 for smooth, frames = 10**29 for simulate."""
    config = tmp_path / "in" / "c.toml"
    config.write_text("# comment\nkeyframe_dt = 1e308\n")
    got = cli(
        ["smooth", planar_log, "--out", tmp_path / "o", "--config", config], out=tmp_path / "o"
    )
    assert got.code == exitcodes.BAD_INPUT
    assert re.search(r"c\.toml: line 2: RunOptions\.keyframe_dt must be", got.error_line), got.err
    config.write_text(f"frames = {HUGE_INT}\n")
    got = cli(
        ["simulate", "dual-robot-room", "--out", tmp_path / "o", "--config", config],
        out=tmp_path / "o",
    )
    assert got.code == exitcodes.BAD_INPUT
    assert re.search(r"c\.toml: line 1: DualRoomConfig\.frames must be", got.error_line), got.err


@pytest.mark.timeout(60)
def test_a_valid_table_of_a_simulate_config_file_is_taken(cli, tmp_path):
    """Found by the battery: `simulate` parsed a config file's nested tables twice, so even a
    valid `[lidar]` table of dual-robot-room was refused ("expected a table")."""
    config = tmp_path / "in" / "room.toml"
    config.parent.mkdir()
    config.write_text("frames = 3\n[lidar]\nbeams = 32\n")
    out = tmp_path / "room"
    got = cli(["simulate", "dual-robot-room", "--out", out, "--config", config], out=out)
    assert got.code == exitcodes.OK, got.err
    meta = (out / "meta.json").read_text()
    assert '"beams": 32' in meta, meta[:500]
