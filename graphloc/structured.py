"""JSON, YAML and TOML files read one way (size, nesting and value count bounded, nothing
executed; every refusal a `BadStructure` naming the file) and JSON written one way
(`dumps_json`: NumPy values and paths as JSON)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

from graphloc.textio import check_file, read_text

MAX_DEPTH = 64  # levels of nested lists / objects (a manifest needs 6)
MAX_TEXT_BYTES = 16 << 20  # a manifest, topics file, config file or setup JSON
MAX_DATA_BYTES = 1 << 30  # an online checkpoint
MAX_VALUES = 5_000_000  # values in one parsed document (YAML aliases counted where used)


class BadStructure(ValueError):
    """A structured file graphloc refuses; the message names the file."""


def _walk(obj, where: str, what: str, max_values: int) -> None:
    """BadStructure unless `obj` is nested at most MAX_DEPTH levels and holds at most
    `max_values` values (an explicit stack: no recursion)."""
    stack = [(obj, 1)]
    seen = 0
    while stack:
        node, depth = stack.pop()
        seen += 1
        if seen > max_values:
            raise BadStructure(
                f"{where}: {what} holds more than {max_values} values (YAML aliases are "
                f"counted where they are used), more than graphloc reads"
            )
        if isinstance(node, dict):
            children = node.values()
        elif isinstance(node, (list, tuple)):
            children = node
        else:
            continue
        if depth > MAX_DEPTH:
            raise _too_deep(where, what)
        stack.extend((child, depth + 1) for child in children)


def _too_deep(where: str, what: str) -> BadStructure:
    return BadStructure(
        f"{where}: {what} nested deeper than {MAX_DEPTH} levels, more than graphloc reads"
    )


def _sized_text(path: Path, what: str, max_bytes: int) -> str:
    """The text of `path` after `check_file` and the size bound."""
    check_file(path, what=what)
    size = path.stat().st_size
    if size > max_bytes:
        raise BadStructure(
            f"{path}: {size} bytes, larger than the {max_bytes} bytes a {what} may have"
        )
    return read_text(path)


# ---- JSON ---------------------------------------------------------------------------------------
def _reject_constant(name: str):
    raise ValueError(f"{name} is not a finite number")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):  # 1e400: no constant, but not a finite number either
        raise ValueError(f"{text} is not a finite number")
    return value


def parse_json(
    text: str,
    where: str,
    what: str = "JSON",
    allow_nan: bool = True,
    max_values: int = MAX_VALUES,
):
    """`text` parsed as JSON; BadStructure naming `where` (and the line of a syntax error)
    when it is not JSON, holds NaN / Infinity without `allow_nan`, or is too deep or too big."""
    try:
        data = json.loads(
            text,
            parse_constant=None if allow_nan else _reject_constant,
            parse_float=None if allow_nan else _finite_float,
        )
    except json.JSONDecodeError as exc:
        raise BadStructure(f"{where}: line {exc.lineno}: invalid JSON ({exc.msg})") from None
    except RecursionError:
        raise _too_deep(where, what) from None
    except ValueError as exc:  # a NaN / Infinity constant refused
        raise BadStructure(f"{where}: invalid {what}: {exc}") from None
    _walk(data, where, what, max_values)
    return data


def read_json(path, what: str = "JSON file", max_bytes: int = MAX_TEXT_BYTES, allow_nan=True):
    """A JSON file a user gives (manifest, setup): `_sized_text` then `parse_json`."""
    path = Path(path)
    return parse_json(_sized_text(path, what, max_bytes), str(path), what, allow_nan)


def dumps_json(obj, *, default=None, **kwargs) -> str:
    """`json.dumps` with NumPy scalars and arrays as JSON values and paths as strings (then
    `default`, if given, for anything else)."""

    def fallback(value):
        np = sys.modules.get("numpy")  # not imported: no NumPy value can exist (a light import)
        if np is not None and isinstance(value, (np.generic, np.ndarray)):
            return value.tolist()
        if isinstance(value, Path):
            return str(value)
        if default is None:
            raise TypeError(f"Object of type {type(value).__name__} is not JSON serializable")
        return default(value)

    return json.dumps(obj, default=fallback, **kwargs)


# ---- YAML, TOML ---------------------------------------------------------------------------------
def read_yaml(path, what: str = "YAML file", max_bytes: int = MAX_TEXT_BYTES):
    """A YAML file (`yaml.safe_load`: plain data, never code): size, depth and values bounded
    (an alias bomb is refused when its expansion passes `MAX_VALUES`); BadStructure naming the
    file (and the line of a syntax error)."""
    import yaml

    path = Path(path)
    text = _sized_text(path, what, max_bytes)
    try:
        data = yaml.safe_load(text)
    except RecursionError:
        raise _too_deep(str(path), what) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f"line {mark.line + 1}: " if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise BadStructure(f"{path}: {line}not valid YAML ({problem})") from None
    _walk(data, str(path), what, max_values=1_000_000)
    return data


def read_toml(path, what: str = "config file", max_bytes: int = MAX_TEXT_BYTES):
    """A TOML file -> (its tables as a dict, its text); size and depth bounded, non-finite
    numbers (TOML's nan, inf) kept for the caller's range checks; BadStructure naming the file
    (and the line and column of a syntax error)."""
    import tomllib

    path = Path(path)
    text = _sized_text(path, what, max_bytes)
    try:
        data = tomllib.loads(text)
    except RecursionError:
        raise _too_deep(str(path), what) from None
    except tomllib.TOMLDecodeError as exc:
        raise BadStructure(f"{path}: not valid TOML: {exc}") from None
    _walk(data, str(path), what, MAX_VALUES)
    return data, text


def finite_number(value) -> bool:
    """A JSON / TOML number that is a finite real (not a bool; an integer too large for a
    float is not finite)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False
