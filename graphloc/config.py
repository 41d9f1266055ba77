"""One way to validate config dataclasses and to turn their fields into options.

`check(self, ...)` in a frozen dataclass's `__post_init__` states the rules of its fields
declaratively; a violation raises ValueError naming `Class.field`, the rule and the value:

    @dataclass(frozen=True)
    class TrackerConfig:
        max_hypotheses: int = 8
        commit_threshold: float = 0.95
        release_threshold: float = 0.5

        def __post_init__(self):
            check(self, integer={"max_hypotheses": 1},
                  interval={"commit_threshold": (0.5, 1.0, "[)"),
                            "release_threshold": (0.0, "commit_threshold", "(]")})

`parse_overrides` turns KEY=VALUE strings (or TOML / JSON values) into typed field values;
`add_config_arguments` derives one `--field-name` option per scalar field (type, default and
help from the field's metadata["help"]) and `config_from_args` builds the config from the
parsed options (defaults < `--config FILE.toml` < command line), so verbs do not copy fields
by hand.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import numbers
import tomllib
import typing
from pathlib import Path

BRACKETS = ("()", "(]", "[)", "[]")


def _name(obj) -> str:
    return type(obj).__name__


def _fail(obj, field: str, rule: str, value) -> ValueError:
    return ValueError(f"{_name(obj)}.{field} must be {rule}, got {value!r}")


def _number(obj, field: str, value, rule: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or math.isnan(value):
        raise _fail(obj, field, rule, value)
    return float(value)


def check(
    obj,
    *,
    positive=(),
    nonnegative=(),
    integer: dict | None = None,
    interval: dict | None = None,
    choices: dict | None = None,
    optional=(),
) -> None:
    """Raise ValueError naming `Class.field` and its value unless every rule holds.

    positive: finite numbers > 0; nonnegative: finite numbers >= 0; integer: {field: minimum}
    integers (not bool) >= minimum; interval: {field: (low, high, brackets)} numbers in the
    interval, brackets one of "()", "(]", "[)", "[]", a bound may name another field;
    choices: {field: allowed values}; optional: fields that may also be None (then unchecked).
    """
    integer, interval, choices = integer or {}, interval or {}, choices or {}
    skip = {f for f in optional if getattr(obj, f) is None}
    for f in positive:
        if f not in skip:
            v = getattr(obj, f)
            if not (math.isfinite(_number(obj, f, v, "finite and > 0")) and v > 0):
                raise _fail(obj, f, "finite and > 0", v)
    for f in nonnegative:
        if f not in skip:
            v = getattr(obj, f)
            if not (math.isfinite(_number(obj, f, v, "finite and >= 0")) and v >= 0):
                raise _fail(obj, f, "finite and >= 0", v)
    for f, low in integer.items():
        if f not in skip:
            v = getattr(obj, f)
            rule = f"an integer >= {low}"
            if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < low:
                raise _fail(obj, f, rule, v)
    for f, (low, high, brackets) in interval.items():
        if f in skip:
            continue
        if brackets not in BRACKETS:
            raise ValueError(f"check: brackets of {_name(obj)}.{f} must be one of {BRACKETS}")
        lo = getattr(obj, low) if isinstance(low, str) else low
        hi = getattr(obj, high) if isinstance(high, str) else high
        rule = f"in {brackets[0]}{_bound(low, lo)}, {_bound(high, hi)}{brackets[1]}"
        v = _number(obj, f, getattr(obj, f), rule)
        above = v >= lo if brackets[0] == "[" else v > lo
        below = v <= hi if brackets[1] == "]" else v < hi
        if not (above and below):
            raise _fail(obj, f, rule, getattr(obj, f))
    for f, allowed in choices.items():
        if f not in skip and getattr(obj, f) not in allowed:
            raise _fail(obj, f, f"one of {tuple(allowed)}", getattr(obj, f))


def _bound(spec, value) -> str:
    return f"{spec} = {value:g}" if isinstance(spec, str) else f"{value:g}"


# ---- values from strings, TOML and the command line -------------------------------------------
def parse_overrides(config_class: type, overrides: dict) -> dict:
    """KEY=VALUE strings (or values) -> typed fields of `config_class`; unknown keys and
    unparsable values raise ValueError naming the field. A string for a non-string field is
    read as JSON (numbers, true / false, lists)."""
    known = {f.name: f for f in dataclasses.fields(config_class)}
    defaults = config_class()
    hints = typing.get_type_hints(config_class)
    out = {}
    for key, value in overrides.items():
        if key not in known:
            raise ValueError(
                f"{config_class.__name__}: unknown field {key!r}; known: {', '.join(sorted(known))}"
            )
        default = getattr(defaults, key)
        kind = _scalar_type(hints.get(key))
        if default is None and kind is not None:  # an optional field: its declared type
            if kind is str and isinstance(value, str):
                out[key] = value
                continue
            default = kind()
        if isinstance(value, str) and not isinstance(default, str):
            try:
                value = json.loads(value)
            except json.JSONDecodeError:
                raise ValueError(f"{config_class.__name__}.{key}: cannot parse {value!r}") from None
        if isinstance(default, bool) != isinstance(value, bool) or (
            isinstance(default, (int, float)) and not isinstance(value, (int, float))
        ):
            raise ValueError(
                f"{config_class.__name__}.{key}: expected {type(default).__name__}, got {value!r}"
            )
        if isinstance(default, int) and not isinstance(default, bool) and value != int(value):
            raise ValueError(f"{config_class.__name__}.{key}: expected an integer, got {value!r}")
        out[key] = (
            type(default)(value)
            if isinstance(default, (int, float)) and not isinstance(default, bool)
            else value
        )
    return out


def _scalar_type(hint) -> type | None:
    """bool / int / float / str for a field annotated with one of them or `X | None`."""
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    if args and len(args) == 1:
        hint = args[0]
    return hint if hint in (bool, int, float, str) else None


def option_fields(config_class: type, exclude=()) -> dict[str, type]:
    """Fields of `config_class` that become options: field name -> bool / int / float / str."""
    hints = typing.get_type_hints(config_class)
    out = {}
    for f in dataclasses.fields(config_class):
        kind = _scalar_type(hints.get(f.name))
        if kind is not None and f.init and f.name not in exclude:
            out[f.name] = kind
    return out


def add_config_arguments(parser: argparse.ArgumentParser, config_class: type, exclude=()) -> None:
    """One `--field-name` option per scalar field of `config_class` (bool fields:
    `--name` / `--no-name`); help from the field's metadata["help"] and its default. Unset
    options stay out of the namespace (`config_from_args` keeps the default)."""
    group = parser.add_argument_group(f"{config_class.__name__} options")
    defaults = config_class()
    for f in dataclasses.fields(config_class):
        kind = option_fields(config_class, exclude).get(f.name)
        if kind is None:
            continue
        text = f.metadata.get("help", "")
        text = f"{text} (default {getattr(defaults, f.name)!r})".strip()
        flag = "--" + f.name.replace("_", "-")
        if kind is bool:
            group.add_argument(
                flag, action=argparse.BooleanOptionalAction, default=argparse.SUPPRESS, help=text
            )
        else:
            group.add_argument(
                flag, type=str, default=argparse.SUPPRESS, metavar=kind.__name__.upper(), help=text
            )


def config_from_args(config_class: type, args: argparse.Namespace, base=None, exclude=()):
    """`base` (default: `config_class()`) with the values of a TOML file `args.config` (when the
    namespace has one; keys are field names, '-' or '_') and then the options given on the
    command line; every value checked by `parse_overrides` and the class's own rules."""
    values: dict = {}
    path = getattr(args, "config", None)
    if path is not None:
        try:
            data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise ValueError(f"{path}: cannot read config: {exc}") from None
        values.update({key.replace("-", "_"): value for key, value in data.items()})
        try:
            parse_overrides(config_class, values)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None
    for name in option_fields(config_class, exclude):
        if hasattr(args, name):
            values[name] = getattr(args, name)
    base = config_class() if base is None else base
    return dataclasses.replace(base, **parse_overrides(config_class, values))
