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
by hand. A field whose default is itself a config dataclass is a TOML table of its name
(`[fusion]`, `[fusion.registration]`, ...); a tuple field a TOML array. `read_config_file`
reads the file through `graphloc.structured.read_toml` (size and nesting bounded); every error
names the file, the line and the field
(`ConfigError.key`: the field's dotted path).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import numbers
import re
import typing
from pathlib import Path

from graphloc.structured import BadStructure, parse_json, read_toml

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

    positive: finite numbers > 0; nonnegative: finite numbers >= 0; integer: {field: minimum
    or (minimum, maximum)} integers (not bool) >= minimum (and <= maximum); interval: {field:
    (low, high, brackets)} numbers in the interval, brackets one of "()", "(]", "[)", "[]", a
    bound may name another field;
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
    for f, bounds in integer.items():
        if f not in skip:
            v = getattr(obj, f)
            low, high = bounds if isinstance(bounds, tuple) else (bounds, None)
            rule = f"an integer >= {low}" if high is None else f"an integer in [{low}, {high}]"
            if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < low:
                raise _fail(obj, f, rule, v)
            if high is not None and v > high:
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
class ConfigError(ValueError):
    """A bad key or value of a config; `key` is the field's dotted path (`fusion.registration
    .voxel`), which `config_values` turns into the line of a config file."""

    def __init__(self, message: str, key: str):
        super().__init__(message)
        self.key = key


def parse_overrides(config_class: type, overrides: dict) -> dict:
    """KEY=VALUE strings (or values) -> typed fields of `config_class`; unknown keys and
    unparsable values raise ConfigError naming the field. A string for a non-string field is
    read as JSON (numbers, true / false, lists); a dict for a field whose default is a config
    dataclass fills that dataclass (recursively); a list for a tuple field becomes a tuple."""
    known = {f.name: f for f in dataclasses.fields(config_class)}
    defaults = config_class()
    hints = typing.get_type_hints(config_class)
    name = config_class.__name__
    out = {}
    for key, value in overrides.items():
        if key not in known:
            raise ConfigError(
                f"{name}: unknown field {key!r}; known: {', '.join(sorted(known))}", key
            )
        default = getattr(defaults, key)
        if dataclasses.is_dataclass(default) and isinstance(value, type(default)):
            out[key] = value  # already parsed (a config file's table, passed on)
            continue
        if dataclasses.is_dataclass(default):
            out[key] = _nested(config_class, key, default, value)
            continue
        kind = _scalar_type(hints.get(key))
        if default is None and kind is not None:  # an optional field: its declared type
            if kind is str and isinstance(value, str):
                out[key] = value
                continue
            default = kind()
        if isinstance(value, str) and not isinstance(default, str):
            try:
                value = parse_json(value, f"{name}.{key}", "value")
            except BadStructure:
                kind_name = "list" if isinstance(default, tuple) else type(default).__name__
                raise ConfigError(
                    f"{name}.{key}: expected {kind_name}, got {value!r}", key
                ) from None
        if isinstance(default, tuple):
            out[key] = _tuple(config_class, key, default, value, hints.get(key))
            continue
        if isinstance(default, bool) != isinstance(value, bool) or (
            isinstance(default, (int, float)) and not isinstance(value, (int, float))
        ):
            raise ConfigError(
                f"{name}.{key}: expected {type(default).__name__}, got {value!r}", key
            )
        if isinstance(default, str) and not isinstance(value, str):
            raise ConfigError(f"{name}.{key}: expected str, got {value!r}", key)
        if isinstance(default, (int, float)) and not isinstance(default, bool):
            _bounded(f"{name}.{key}", key, value, integer=isinstance(default, int))
        out[key] = (
            type(default)(value)
            if isinstance(default, (int, float)) and not isinstance(default, bool)
            else value
        )
    return out


MAX_OPTION = 1e9  # the largest |value| of any numeric option (a class may state less)
MAX_OPTION_INT = 2**32  # integers below it (a seed may be any 32-bit unsigned number)


def _bounded(name: str, key: str, value, integer: bool) -> None:
    """ConfigError naming the field unless `value` is a finite number within +-MAX_OPTION
    (an integer within +-MAX_OPTION_INT, no fraction, for an integer field): whatever a class
    states of its own fields, no option is NaN, inf or beyond any sane size."""
    if integer:
        if not (isinstance(value, int) or (math.isfinite(value) and value == int(value))):
            raise ConfigError(f"{name}: expected an integer, got {value!r}", key)
        if abs(value) >= MAX_OPTION_INT:
            raise ConfigError(
                f"{name} must be an integer within +-{MAX_OPTION_INT}, got {value!r}", key
            )
    elif not (math.isfinite(value) and abs(value) <= MAX_OPTION):
        raise ConfigError(
            f"{name} must be a finite number within +-{MAX_OPTION:g}, got {value!r}", key
        )


def _nested(config_class: type, key: str, default, value):
    """A table of fields -> the nested config dataclass `default` with them, checked by its
    own rules (errors carry the dotted path of the bad field)."""
    name = f"{config_class.__name__}.{key}"
    if not isinstance(value, dict):
        raise ConfigError(f"{name}: expected a table of {type(default).__name__} fields", key)
    try:
        return dataclasses.replace(default, **parse_overrides(type(default), value))
    except ConfigError as exc:
        raise ConfigError(f"{name}: {exc}", f"{key}.{exc.key}") from None
    except (TypeError, ValueError) as exc:
        field = _named_field(str(exc), type(default))
        raise ConfigError(f"{name}: {exc}", f"{key}.{field}" if field else key) from None


def _tuple(config_class: type, key: str, default: tuple, value, hint) -> tuple:
    """A list for a tuple field: the default's length (any length for `tuple[X, ...]`), each
    element of the annotated type."""
    name = f"{config_class.__name__}.{key}"
    args = typing.get_args(hint)
    variable = len(args) == 2 and args[1] is Ellipsis
    if (
        not isinstance(value, (list, tuple))
        or not value
        or (not variable and len(value) != len(default))
    ):
        size = "one or more" if variable else str(len(default))
        raise ConfigError(f"{name}: expected a list of {size} values, got {value!r}", key)
    kinds = [args[0]] * len(value) if variable else list(args) or [type(v) for v in default]
    out = []
    for v, kind in zip(value, kinds):
        number = isinstance(v, numbers.Real) and not isinstance(v, bool)
        ok = {
            float: number,
            int: number and math.isfinite(v) and v == int(v),
            bool: isinstance(v, bool),
            str: isinstance(v, str),
        }.get(kind, True)
        if not ok:
            raise ConfigError(f"{name}: expected {kind.__name__} values, got {value!r}", key)
        if kind in (float, int):
            _bounded(name, key, v, integer=kind is int)
        out.append(kind(v) if kind in (float, int) else v)
    return tuple(out)


def _named_field(message: str, config_class: type) -> str | None:
    """The field of `config_class` an error message names as `Class.field`, if any."""
    m = re.search(rf"\b{config_class.__name__}\.(\w+)", message)
    names = {f.name for f in dataclasses.fields(config_class)}
    return m.group(1) if m and m.group(1) in names else None


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


def read_config_file(path) -> tuple[dict, dict]:
    """A TOML config file -> (its tables as a dict with '-' in keys read as '_', {dotted key:
    line number}). Opened through `graphloc.textio` (a missing file, a directory or bytes that
    are not UTF-8 are errors naming the file and line); a syntax error names file, line and
    column."""
    data, text = read_toml(Path(path))
    return _underscored(data), _key_lines(text)


def _underscored(data: dict) -> dict:
    return {
        k.replace("-", "_"): _underscored(v) if isinstance(v, dict) else v for k, v in data.items()
    }


_TABLE = re.compile(r"^\s*\[\s*([A-Za-z0-9_.\- ]+?)\s*\]\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_\-]+)\s*=")


def _key_lines(text: str) -> dict:
    """{dotted key (tables too): line} of a TOML text's `[table]` headers and `key =` lines."""
    lines, table = {}, ""
    for n, line in enumerate(text.splitlines(), start=1):
        m = _TABLE.match(line)
        if m:
            table = m.group(1).replace(" ", "").replace("-", "_")
            lines.setdefault(table, n)
            continue
        m = _KEY.match(line)
        if m:
            key = m.group(1).replace("-", "_")
            lines.setdefault(f"{table}.{key}" if table else key, n)
    return lines


def _where(path, lines: dict, key: str | None) -> str:
    """`FILE: line N: ` for the dotted key (or its nearest table) of a config file."""
    parts = key.split(".") if key else []
    while parts and ".".join(parts) not in lines:
        parts.pop()
    return f"{path}: line {lines['.'.join(parts)]}: " if parts else f"{path}: "


def config_values(config_class: type, args: argparse.Namespace, exclude=()) -> dict:
    """The typed field values of `config_class` given by a TOML file `args.config` (when the
    namespace has one; `read_config_file`) and then by the command line, which wins; every
    error from the file names file, line and field."""
    values: dict = {}
    path = getattr(args, "config", None)
    lines: dict = {}
    if path is not None:
        data, lines = read_config_file(path)
        try:
            values.update(parse_overrides(config_class, data))
        except ConfigError as exc:
            raise ValueError(f"{_where(path, lines, exc.key)}{exc}") from None
    given = {n: getattr(args, n) for n in option_fields(config_class, exclude) if hasattr(args, n)}
    values.update(parse_overrides(config_class, given))
    return values


def config_from_args(config_class: type, args: argparse.Namespace, base=None, exclude=()):
    """`base` (default: `config_class()`) with `config_values`: defaults < `--config FILE`
    < command line, checked by `parse_overrides` and the class's own rules (an error of a
    value from the file names file, line and field)."""
    values = config_values(config_class, args, exclude)
    base = config_class() if base is None else base
    try:
        return dataclasses.replace(base, **values)
    except ValueError as exc:
        path = getattr(args, "config", None)
        field = _named_field(str(exc), config_class)
        if path is None or field is None or hasattr(args, field):
            raise
        _, lines = read_config_file(path)
        raise ValueError(f"{_where(path, lines, field)}{exc}") from None
