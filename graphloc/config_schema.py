"""Config classes: frozen dataclasses checked by pydantic in strict mode, their rules stated once
as field constraints (`setting`), which `graphloc.config` also turns into command-line options
and config-file keys (docs/design_core.md, "Configuration")."""

from __future__ import annotations

import dataclasses
import functools
import inspect
import re
import typing

# pydantic's strict mode for every config class (`__pydantic_config__`, a plain dict: read
# by pydantic when it builds the validator, so no pydantic import where classes are defined)
STRICT = {
    "strict": True,
    "allow_inf_nan": False,
    "extra": "forbid",
    "arbitrary_types_allowed": True,
}
FIELD_ARGS = ("gt", "ge", "lt", "le", "allow_inf_nan", "description")
# pydantic's error types of a value of the wrong type (text for a number, a fraction for an int)
TYPE_ERRORS = ("bool_type", "int_type", "float_type", "string_type")


class ConfigError(ValueError):
    """A bad key or value of a config; `key` is the field's dotted path (`fusion.registration
    .voxel`), which `config_values` turns into the line of a config file."""

    def __init__(self, message: str, key: str):
        super().__init__(message)
        self.key = key


def setting(default=dataclasses.MISSING, *, default_factory=dataclasses.MISSING, **rules):
    """A dataclass field whose metadata are pydantic `Field` arguments (`FIELD_ARGS`): bounds
    (gt, ge, lt, le), `allow_inf_nan` and the `description` that is the option's help."""
    unknown = sorted(set(rules) - set(FIELD_ARGS))
    if unknown:
        raise TypeError(f"setting: unknown rules {unknown}; known: {', '.join(FIELD_ARGS)}")
    return dataclasses.field(default=default, default_factory=default_factory, metadata=rules)


def config_dataclass(cls):
    """`cls` as a frozen dataclass whose `__init__` is pydantic's strict validation of its
    fields (then its `__post_init__`); errors are `ConfigError`s naming class, field, rule and
    value."""
    cls.__pydantic_config__ = STRICT
    cls = dataclasses.dataclass(frozen=True)(cls)

    def __init__(self, *args, **kwargs):
        validator, error_type, args_kwargs = _validator(type(self))
        try:
            validator.validate_python(args_kwargs(args, kwargs), self_instance=self)
        except error_type as exc:
            raise _config_error(type(self), exc.errors(include_url=False)[0]) from None

    __init__.__signature__ = inspect.signature(cls.__init__)  # the fields, for help() / IDEs
    __init__.__qualname__ = f"{cls.__qualname__}.__init__"
    __init__.__doc__ = f"{cls.__name__}'s fields, checked by pydantic (graphloc.config)."
    cls.__init__ = __init__
    return cls


@functools.cache
def _validator(cls: type):
    """pydantic's validator of dataclass `cls`, built once (pydantic is imported here)."""
    from pydantic import TypeAdapter, ValidationError
    from pydantic_core import ArgsKwargs

    return TypeAdapter(cls).validator, ValidationError, ArgsKwargs


def _config_error(cls: type, error: dict) -> ConfigError:
    """One pydantic error dict -> ConfigError `Class.field must be RULE, got VALUE`."""
    loc = [str(part) for part in error["loc"]]
    path = ".".join([cls.__name__, *loc])
    key = ".".join(loc)
    if error["type"] == "value_error":  # a class's __post_init__: its own words
        text = str(error["ctx"]["error"])
        if loc:
            return ConfigError(f"{path}: {text}", key)
        return ConfigError(text, _named_field(text, cls) or "")
    if error["type"] == "unexpected_keyword_argument":
        known = ", ".join(f.name for f in dataclasses.fields(cls) if f.init)
        return ConfigError(f"{cls.__name__}: unknown field {key!r}; known: {known}", key)
    found = _field_at(cls, loc)
    if found is not None:
        depth, hint, rules = found
        rule = _rule(hint, rules)
        if _is_tuple(hint) and error["type"] != "tuple_type":  # a TOML array's length / items
            field_path = ".".join([cls.__name__, *loc[: depth + 1]])
            size, kind = _tuple_shape(hint)
            if depth + 1 < len(loc) and error["type"] != "missing":
                return ConfigError(
                    f"{field_path}: expected {kind} values, got {error['input']!r}", key
                )
            return ConfigError(
                f"{field_path}: expected a list of {size} values, got {error['input']!r}", key
            )
        kind = scalar_type(hint)
        if error["type"] in TYPE_ERRORS and kind is not None and depth + 1 == len(loc):
            return ConfigError(f"{path}: expected {kind.__name__}, got {error['input']!r}", key)
        if rule is not None and depth + 1 == len(loc):
            return ConfigError(f"{path} must be {rule}, got {error['input']!r}", key)
    return ConfigError(f"{path}: {error['msg']}, got {error['input']!r}", key)  # pydantic's


def _named_field(message: str, cls: type) -> str | None:
    """The field of `cls` a rule across fields names as `Class.field` in its message (the
    line of a config file it points to), if any."""
    m = re.search(rf"\b{cls.__name__}\.(\w+)", message)
    names = {f.name for f in dataclasses.fields(cls)}
    return m.group(1) if m and m.group(1) in names else None


def _field_at(cls: type, loc: list[str]):
    """(index in `loc`, annotation, metadata) of the field an error location points into,
    nested config fields followed; None if it names no field."""
    for depth, name in enumerate(loc):
        found = {f.name: f for f in dataclasses.fields(cls)}.get(name)
        if found is None:
            return None
        hint = typing.get_type_hints(cls)[name]
        inner = _unwrap_optional(hint)
        if depth + 1 == len(loc) or not dataclasses.is_dataclass(inner):
            return depth, hint, found.metadata
        cls = inner
    return None


def _rule(hint, rules) -> str | None:
    """The rule of a field, from its annotation (choices) and its metadata (bounds)."""
    choices = choices_of(hint)
    if choices:
        return f"one of {choices!r}"
    return _bounds_rule(scalar_type(hint), rules)


def _is_tuple(hint) -> bool:
    hint = _unwrap_optional(hint)
    return hint is tuple or typing.get_origin(hint) is tuple


def _tuple_shape(hint) -> tuple[str, str]:
    """(how many, of what) for a tuple annotation: ("2", "float"), ("one or more", "int")."""
    args = typing.get_args(_unwrap_optional(hint))
    if len(args) == 2 and args[1] is Ellipsis:
        return "one or more", getattr(args[0], "__name__", str(args[0]))
    if args:
        kinds = {getattr(a, "__name__", str(a)) for a in args}
        return str(len(args)), kinds.pop() if len(kinds) == 1 else "the annotated"
    return "any number of", "any"


def _bounds_rule(kind, rules) -> str | None:
    low = next(((k, rules[k]) for k in ("gt", "ge") if k in rules), None)
    high = next(((k, rules[k]) for k in ("lt", "le") if k in rules), None)
    if kind is int:
        if low and high:
            return f"an integer in {_interval(low, high)}"
        return "an integer" + (
            f" {_relation(low)}" if low else f" {_relation(high)}" if high else ""
        )
    if kind is float:
        inf = rules.get("allow_inf_nan", False)
        if low and (high or inf):
            return f"in {_interval(low, high)}"
        if low or high:
            return ("" if inf else "finite and ") + _relation(low or high)
        return "a number" if inf else "a finite number"
    return {bool: "true or false", str: "a string"}.get(kind)


def _relation(bound) -> str:
    op = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}[bound[0]]
    return f"{op} {_number(bound[1])}"


def _interval(low, high) -> str:
    left = "(" if low[0] == "gt" else "["
    right = "]" if high is None or high[0] == "le" else ")"
    top = "inf" if high is None else _number(high[1])
    return f"{left}{_number(low[1])}, {top}{right}"


def _number(value) -> str:
    return str(value) if isinstance(value, int) else f"{value:g}"


_UNIONS = (typing.Union, type(int | None))


def _unwrap_optional(hint):
    """X for `X | None`, else `hint`."""
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    return args[0] if typing.get_origin(hint) in _UNIONS and len(args) == 1 else hint


def choices_of(hint) -> tuple:
    hint = _unwrap_optional(hint)
    return typing.get_args(hint) if typing.get_origin(hint) is typing.Literal else ()


def scalar_type(hint) -> type | None:
    """bool / int / float / str for a field annotated with one of them, a `Literal` of strings
    or `X | None`."""
    hint = _unwrap_optional(hint)
    choices = choices_of(hint)
    if choices and all(isinstance(c, str) for c in choices):
        return str
    return hint if hint in (bool, int, float, str) else None
