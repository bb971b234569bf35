"""Load TOML configuration into typed, frozen dataclasses; validate in one place.

Every configuration object of the project is a frozen dataclass. Its fields carry their type
hints (``int``, ``float``, ``bool``, ``str``, ``Literal[...]``, ``tuple[float, ...]``, a nested
dataclass, or ``X | None``) and optional bounds in the field metadata::

    alpha: float = field(default=0.05, metadata={"gt": 0.0, "lt": 1.0, "doc": "false-alarm rate"})

:func:`load_dataclass` checks a TOML table against the class: unknown keys, wrong types and
values out of range fail with a :class:`~fdi.errors.ConfigError` that names the file, the dotted
key, what was expected and what was found. Missing keys take the dataclass default, so a preset
only states what it changes, and the built-in defaults are the dataclass defaults.
"""

from __future__ import annotations

import dataclasses
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin, get_type_hints

from fdi.errors import ConfigError

T = TypeVar("T")

_BOUND_TEXT = {"ge": ">=", "gt": ">", "le": "<=", "lt": "<"}


def _found(value: object) -> str:
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{text} ({type(value).__name__})"


def _describe(tp: Any) -> str:
    origin = get_origin(tp)
    if tp is int:
        return "an integer"
    if tp is float:
        return "a number"
    if tp is bool:
        return "true or false"
    if tp is str:
        return "a string"
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(tp))
    if origin in (tuple, list):
        args = [a for a in get_args(tp) if a is not Ellipsis]
        inner = _describe(args[0]) if args else "values"
        return f"a list of {inner.removeprefix('an ').removeprefix('a ')}s"
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(a) for a in get_args(tp) if a is not type(None))
    if dataclasses.is_dataclass(tp):
        return f"a table [{getattr(tp, '__name__', tp)}]"
    return str(tp)


def _convert(value: Any, tp: Any, file: str, key: str) -> Any:
    origin = get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        for arg in args:
            try:
                return _convert(value, arg, file, key)
            except ConfigError:
                if isinstance(value, dict) and dataclasses.is_dataclass(arg):
                    raise  # a table for a table-typed key: its own error is the precise one
        raise ConfigError(file, key, _describe(tp), _found(value))
    if tp is bool:
        if isinstance(value, bool):
            return value
    elif tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif tp is float:
        if isinstance(value, int | float) and not isinstance(value, bool):
            return float(value)
    elif tp is str:
        if isinstance(value, str):
            return value
    elif origin is Literal:
        if value in get_args(tp) and isinstance(value, str | int):
            return value
    elif origin in (tuple, list):
        if isinstance(value, list):
            args = [a for a in get_args(tp) if a is not Ellipsis]
            inner = args[0] if args else Any
            items = [
                _convert(v, inner, file, f"{key}[{i}]") if inner is not Any else v
                for i, v in enumerate(value)
            ]
            return tuple(items) if origin is tuple else items
    elif dataclasses.is_dataclass(tp) and isinstance(tp, type):
        if isinstance(value, dict):
            return load_dataclass(tp, value, file, key)
    elif tp is Any:
        return value
    raise ConfigError(file, key, _describe(tp), _found(value))


def _check_bounds(value: Any, meta: typing.Mapping[str, Any], file: str, key: str) -> None:
    if not isinstance(value, int | float) or isinstance(value, bool):
        return
    for name, op in _BOUND_TEXT.items():
        if name not in meta:
            continue
        bound = meta[name]
        ok = {
            "ge": value >= bound,
            "gt": value > bound,
            "le": value <= bound,
            "lt": value < bound,
        }[name]
        if not ok:
            raise ConfigError(file, key, f"a number {op} {bound}", _found(value))


def load_dataclass(cls: type[T], table: dict[str, Any], file: str, prefix: str = "") -> T:
    """Build ``cls`` from a TOML table, validating every key (see the module docstring)."""
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    hints = get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kwargs: dict[str, Any] = {}
    for key, value in table.items():
        dotted = f"{prefix}.{key}" if prefix else key
        if key not in fields:
            known = ", ".join(sorted(fields))
            raise ConfigError(file, dotted, f"one of the keys {known}", "an unknown key")
        fld = fields[key]
        converted = _convert(value, hints[key], file, dotted)
        _check_bounds(converted, fld.metadata, file, dotted)
        if isinstance(converted, tuple | list):
            for i, item in enumerate(converted):
                _check_bounds(item, fld.metadata, file, f"{dotted}[{i}]")
        kwargs[key] = converted
    try:
        obj = cls(**kwargs)
    except (TypeError, ValueError) as err:  # __post_init__ cross-checks
        raise ConfigError(file, prefix or "(top level)", "consistent values", str(err)) from err
    return typing.cast(T, obj)


def read_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file, translating I/O and syntax errors into :class:`ConfigError`."""
    p = Path(path)
    try:
        text = p.read_bytes()
    except OSError as err:
        found = err.strerror or str(err)
        raise ConfigError(str(p), "(file)", "a readable TOML file", found) from err
    try:
        return tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError as err:
        raise ConfigError(str(p), "(file)", "UTF-8 text", f"invalid byte at {err.start}") from err
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(str(p), "(syntax)", "valid TOML", str(err)) from err


def load_file(cls: type[T], path: str | Path) -> T:
    """Read ``path`` and build ``cls`` from its top-level table."""
    return load_dataclass(cls, read_toml(path), str(path))
