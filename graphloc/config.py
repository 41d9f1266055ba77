"""A config dataclass's fields as command-line options and TOML config-file keys (defaults <
`--config FILE.toml` < command line); every error names the file, the line and the field."""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
import typing
from pathlib import Path

from graphloc.config_schema import ConfigError, choices_of, scalar_type
from graphloc.structured import BadStructure, parse_json, read_toml


def parse_overrides(config_class: type, overrides: dict) -> dict:
    """KEY=VALUE strings (or values) -> field values of `config_class`: strings read as JSON, tables
    as nested config dataclasses, lists as tuples, numbers bounded (`_bounded`); ConfigError
    names the field."""
    known = {f.name: f for f in dataclasses.fields(config_class) if f.init}
    hints = typing.get_type_hints(config_class)
    name = config_class.__name__
    out = {}
    for key, value in overrides.items():
        if key not in known:
            raise ConfigError(
                f"{name}: unknown field {key!r}; known: {', '.join(sorted(known))}", key
            )
        default = _default(known[key])
        if dataclasses.is_dataclass(default):
            if not isinstance(value, type(default)):  # else a config file's table, passed on
                value = _nested(config_class, key, default, value)
            out[key] = value
            continue
        if isinstance(value, str) and scalar_type(hints[key]) is not str:
            try:
                value = parse_json(value, f"{name}.{key}", "value")
            except BadStructure:
                kind = scalar_type(hints[key])
                kind_name = kind.__name__ if kind else "list"
                raise ConfigError(
                    f"{name}.{key}: expected {kind_name}, got {value!r}", key
                ) from None
        if isinstance(value, list):
            value = tuple(value)
        for number in value if isinstance(value, tuple) else (value,):
            _bounded(f"{name}.{key}", key, number)
        out[key] = value
    return out


def _default(f: dataclasses.Field):
    return f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default


MAX_OPTION = 1e9  # the largest |value| of any numeric option (a class may state less)
MAX_OPTION_INT = 2**32  # integers below it (a seed may be any 32-bit unsigned number)


def _bounded(name: str, key: str, value) -> None:
    """ConfigError naming the field unless a number `value` is finite and within +-MAX_OPTION
    (an integer within +-MAX_OPTION_INT): whatever a class states of its own fields, no option
    is NaN, inf or beyond any sane size. Other values are left to the class's rules."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return
    if isinstance(value, int) and abs(value) >= MAX_OPTION_INT:
        raise ConfigError(
            f"{name} must be an integer within +-{MAX_OPTION_INT}, got {value!r}", key
        )
    if isinstance(value, float) and not (math.isfinite(value) and abs(value) <= MAX_OPTION):
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
        raise ConfigError(f"{name}: {exc}", f"{key}.{exc.key}" if exc.key else key) from None


def option_fields(config_class: type, exclude=()) -> dict[str, type]:
    """Fields of `config_class` that become options: field name -> bool / int / float / str."""
    hints = typing.get_type_hints(config_class)
    out = {}
    for f in dataclasses.fields(config_class):
        kind = scalar_type(hints.get(f.name))
        if kind is not None and f.init and f.name not in exclude:
            out[f.name] = kind
    return out


def add_config_arguments(parser: argparse.ArgumentParser, config_class: type, exclude=()) -> None:
    """One `--field-name` option per scalar field of `config_class` (bools: `--name` / `--no-name`),
    its help from the field's description, choices and default; unset options stay out of `args`."""
    group = parser.add_argument_group(f"{config_class.__name__} options")
    hints = typing.get_type_hints(config_class)
    kinds = option_fields(config_class, exclude)
    for f in dataclasses.fields(config_class):
        kind = kinds.get(f.name)
        if kind is None:
            continue
        choices = choices_of(hints[f.name])
        text = f.metadata.get("description", "")
        if choices:
            text = f"{text} ({', '.join(map(str, choices))})".strip()
        text = f"{text} (default {_default(f)!r})".strip()
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
    """A TOML config file -> (its tables, '-' in keys read as '_'; {dotted key: line number});
    errors name the file and line."""
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
    """The field values of `config_class` given by a TOML file `args.config` (when the
    namespace has one; `read_config_file`) and then by the command line, which wins; every
    error from the file names file, line and field."""
    values: dict = {}
    path = getattr(args, "config", None)
    if path is not None:
        data, lines = read_config_file(path)
        try:
            values.update(parse_overrides(config_class, data))
        except ConfigError as exc:
            raise ValueError(f"{_where(path, lines, exc.key)}{exc}") from None
    given = {n: getattr(args, n) for n in option_fields(config_class, exclude) if hasattr(args, n)}
    values.update(parse_overrides(config_class, given))
    return values


def config_from_args(config_class: type, args: argparse.Namespace, exclude=()):
    """`config_class` with `config_values`: defaults < `--config FILE` < command line, checked
    by the class's rules (an error of a value from the file names file, line and field)."""
    values = config_values(config_class, args, exclude)
    try:
        return dataclasses.replace(config_class(), **values)
    except ConfigError as exc:
        path = getattr(args, "config", None)
        field = exc.key.split(".")[0] if exc.key else None
        if path is None or field is None or hasattr(args, field):
            raise
        _, lines = read_config_file(path)
        raise ValueError(f"{_where(path, lines, exc.key)}{exc}") from None
