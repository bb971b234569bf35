"""Load TOML configuration into typed, frozen dataclasses; validate in one place.

Every configuration object of the project is a frozen dataclass. Its fields carry their type
hints (``int``, ``float``, ``bool``, ``str``, ``Literal[...]``, ``tuple[float, ...]``, a nested
dataclass, or ``X | None``) and optional bounds in the field metadata::

    alpha: float = field(default=0.05, metadata={"gt": 0.0, "lt": 1.0, "doc": "false-alarm rate"})

:func:`load_dataclass` checks a TOML table against the class: unknown keys, wrong types and
values out of range (bounds ``ge``, ``gt``, ``le``, ``lt``, ``ne``; ``inf`` and ``nan`` are never a
number here; see :func:`check_number` for the floors every float keeps) fail with a
:class:`~fdi.errors.ConfigError` that names the file, the dotted key,
what was expected and what was found; an unknown key says which known key it is close to ("did
you mean"). All the errors of a file are collected (:class:`~fdi.errors.ConfigErrors` when more
than one). Missing keys take the dataclass default, so a preset only states what it changes, and
the built-in defaults are the dataclass defaults. A field with ``metadata={"toml": False}`` is
not a key of the file (the loader fills it in).

The bounds are the one validation of a value wherever it comes from: the MAVLink parameter
table (:mod:`firmware_host.mavlink.params`) is built from the same metadata and refuses a
PARAM_SET with :func:`check_number`, so a ground station cannot set what a file may not hold.
A documented "off" value outside the range (``gate_sigmas = 0``: the fixed gate) is stated as
``"off": 0.0``: that value, or one inside the bounds.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin, get_type_hints

from fdi.errors import ConfigError, ConfigErrors

T = TypeVar("T")

MAX_MAGNITUDE = 1e6
"""A float field without an upper (lower) bound of its own is at most (at least) this. No
setting of the bridge means more (a million seconds is 11 days, a million metres 1 000 km), and
beyond it a time overflows what it feeds (a selector's timeout in milliseconds, a sleep) and a
scale overflows a square (``1e308``)."""

STRICT_MARGIN = 1e-6
"""A strict bound of a float, ``gt: b`` (``lt: b``), is the floor ``b + 1e-6 x max(1, |b|)``
(the ceiling ``b - ...``): a quantity that must be positive is at least a millionth of its unit,
never ``1e-38`` or ``5e-324``, whose reciprocal or square is not a number. A field that needs a
smaller positive value says so with ``ge`` (``alpha``: ``ge = 1e-15``)."""


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


class _Invalid(Exception):
    """A table whose errors are already recorded (one per bad key)."""


def _convert(value: Any, tp: Any, file: str, key: str, errors: list[ConfigError]) -> Any:
    """``value`` as ``tp``; a mismatch of this key raises ConfigError, a nested table's errors
    are recorded in ``errors`` (all of them) and raise :class:`_Invalid`."""
    origin = get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        for arg in args:
            trial: list[ConfigError] = []
            try:
                return _convert(value, arg, file, key, trial)
            except ConfigError:
                continue
            except _Invalid:
                if isinstance(value, dict) and dataclasses.is_dataclass(arg):
                    errors.extend(trial)  # a table for a table-typed key: its own errors
                    raise
        raise ConfigError(file, key, _describe(tp), _found(value))
    if tp is bool:
        if isinstance(value, bool):
            return value
    elif tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif tp is float:
        if isinstance(value, int | float) and not isinstance(value, bool):
            if not math.isfinite(value):  # TOML has inf and nan; no parameter means them
                raise ConfigError(file, key, "a finite number", _found(value))
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
            items: list[Any] = []
            bad = False
            for i, v in enumerate(value):
                try:
                    items.append(_convert(v, inner, file, f"{key}[{i}]", errors))
                except ConfigError as err:
                    errors.append(err)
                    bad = True
                except _Invalid:
                    bad = True
            if bad:
                raise _Invalid
            return tuple(items) if origin is tuple else items
    elif dataclasses.is_dataclass(tp) and isinstance(tp, type):
        if isinstance(value, dict):
            return _load(tp, value, file, key, errors)
    elif tp is Any:
        return value
    raise ConfigError(file, key, _describe(tp), _found(value))


def number_range(meta: typing.Mapping[str, Any], integer: bool) -> tuple[float, float]:
    """The closed range ``[lo, hi]`` a number of a field with this metadata must be in (besides
    its ``off`` value and ``ne``): the bounds as :func:`check_number` applies them."""
    lo, hi = -math.inf, math.inf
    if "ge" in meta:
        lo = float(meta["ge"])
    if "gt" in meta:
        gt = float(meta["gt"])
        strict = math.floor(gt) + 1.0 if integer else gt + STRICT_MARGIN * max(1.0, abs(gt))
        lo = max(lo, strict)
    if "le" in meta:
        hi = float(meta["le"])
    if "lt" in meta:
        lt = float(meta["lt"])
        strict = math.ceil(lt) - 1.0 if integer else lt - STRICT_MARGIN * max(1.0, abs(lt))
        hi = min(hi, strict)
    if integer:
        lo = float(math.ceil(lo)) if math.isfinite(lo) else lo
        hi = float(math.floor(hi)) if math.isfinite(hi) else hi
    else:
        lo = lo if "ge" in meta or "gt" in meta else -MAX_MAGNITUDE
        hi = hi if "le" in meta or "lt" in meta else MAX_MAGNITUDE
    return lo, hi


def check_number(value: float, meta: typing.Mapping[str, Any], integer: bool = False) -> str | None:
    """None when ``value`` passes the bounds of ``meta``; else what was expected (one line).

    ``integer``: the field is an ``int`` (its bounds are exact). A float keeps the floors of
    :data:`STRICT_MARGIN` and :data:`MAX_MAGNITUDE`, and must be finite. ``meta["off"]``, when
    present, is accepted as well (a documented "off")."""
    if not integer and not math.isfinite(value):
        return "a finite number"
    off = meta.get("off")
    if off is not None and value == off:
        return None
    prefix = f"{off!r} (off) or " if off is not None else ""
    lo, hi = number_range(meta, integer)
    if value < lo:  # the bound as stated, else the floor it keeps
        if "ge" in meta and float(meta["ge"]) == lo:
            return f"{prefix}a number >= {meta['ge']}"
        if "gt" in meta and (integer or value <= meta["gt"]):
            return f"{prefix}a number > {meta['gt']}"
        return f"{prefix}a number >= {lo:g}"
    if value > hi:
        if "le" in meta and float(meta["le"]) == hi:
            return f"{prefix}a number <= {meta['le']}"
        if "lt" in meta and (integer or value >= meta["lt"]):
            return f"{prefix}a number < {meta['lt']}"
        return f"{prefix}a number <= {hi:g}"
    if "ne" in meta and value == meta["ne"]:
        return f"a number other than {meta['ne']}"
    return None


def _check_bounds(value: Any, meta: typing.Mapping[str, Any], file: str, key: str) -> None:
    if not isinstance(value, int | float) or isinstance(value, bool):
        return
    expected = check_number(value, meta, integer=isinstance(value, int))
    if expected is not None:
        raise ConfigError(file, key, expected, _found(value))


def _unknown_key(file: str, dotted: str, key: str, known: list[str]) -> ConfigError:
    close = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
    found = f"an unknown key (did you mean {close[0]!r}?)" if close else "an unknown key"
    return ConfigError(file, dotted, "one of the keys " + ", ".join(sorted(known)), found)


def toml_fields(cls: type[Any]) -> dict[str, dataclasses.Field[Any]]:
    """The fields of ``cls`` a TOML table may set (``metadata={"toml": False}``: none)."""
    return {f.name: f for f in dataclasses.fields(cls) if f.metadata.get("toml", True)}


def _load(cls: type[T], table: dict[str, Any], file: str, prefix: str,
          errors: list[ConfigError]) -> T:
    hints = get_type_hints(cls)
    fields = toml_fields(cls)
    kwargs: dict[str, Any] = {}
    n_errors = len(errors)
    for key, value in table.items():
        dotted = f"{prefix}.{key}" if prefix else key
        if key not in fields:
            errors.append(_unknown_key(file, dotted, key, list(fields)))
            continue
        fld = fields[key]
        try:
            converted = _convert(value, hints[key], file, dotted, errors)
            _check_bounds(converted, fld.metadata, file, dotted)
            if isinstance(converted, tuple | list):
                for i, item in enumerate(converted):
                    _check_bounds(item, fld.metadata, file, f"{dotted}[{i}]")
        except ConfigError as err:
            errors.append(err)
            continue
        except _Invalid:
            continue
        kwargs[key] = converted
    if len(errors) > n_errors:
        raise _Invalid
    try:
        obj = cls(**kwargs)
    except (TypeError, ValueError, ArithmeticError) as err:  # __post_init__ cross-checks
        errors.append(ConfigError(file, prefix or "(top level)", "consistent values", str(err)))
        raise _Invalid from err
    return obj


def raise_all(errors: list[ConfigError]) -> None:
    """Raise the errors found in one file: the error itself when one, else
    :class:`~fdi.errors.ConfigErrors` listing all of them in file order."""
    if len(errors) == 1:
        raise errors[0]
    if errors:
        raise ConfigErrors(errors)


def load_dataclass(cls: type[T], table: dict[str, Any], file: str, prefix: str = "") -> T:
    """Build ``cls`` from a TOML table, validating every key (see the module docstring).

    Every bad key of the table is reported, not only the first: one error raises that
    :class:`ConfigError`, several raise :class:`~fdi.errors.ConfigErrors`."""
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    errors: list[ConfigError] = []
    try:
        return _load(cls, table, file, prefix, errors)
    except _Invalid:
        raise_all(errors)
        raise  # unreachable: _Invalid is raised only after recording an error


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
