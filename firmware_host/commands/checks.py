"""Checks of command-line arguments, made before a command's work starts.

Each ``check_*`` function returns its (converted) value or raises
:class:`~fdi.errors.UsageError` with one line naming the option, what was expected and what was
found; :func:`firmware_host.cli.main` turns that into exit status 2. The ``*_arg`` names are the
same checks as ``argparse`` ``type=`` functions, so a bad value is refused while the command line
is parsed (``fdi-bridge replay: error: argument --out: ...``, exit 2) and a 30-second job never
starts with an output it cannot write.

Ports are checked in two steps: the spelling (:func:`~drivers.urls.check_mavlink_url`,
:func:`~drivers.urls.check_serial_url`, in the drivers' layer because the configuration loader
checks the same URLs), and whether a port opens (:func:`check_port_opens`) where a command
must not start without it (``record`` without ``--wait``, ``replay --nmea-out``): that is a
runtime failure (:class:`~fdi.errors.PortError`, exit 1).

This module imports only the standard library, :mod:`drivers.urls` and :mod:`fdi.errors` (the
argument modules that use it must stay light for ``--help``).
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TypeVar

from drivers.urls import MAVLINK_SCHEMES as MAVLINK_SCHEMES
from drivers.urls import SERIAL_SCHEMES as SERIAL_SCHEMES
from drivers.urls import check_mavlink_url as check_mavlink_url
from drivers.urls import check_serial_url as check_serial_url
from fdi.errors import UsageError

T = TypeVar("T")

# --------------------------------------------------------------------------- paths


def _nearest_existing(path: Path) -> Path:
    probe = path.absolute()
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    return probe


def check_input_file(path: str | Path, option: str = "input") -> Path:
    """A file that must exist, be a regular file (not a directory) and be readable."""
    p = Path(path)
    if not p.exists():
        raise UsageError(f"{option} {p}: no such file")
    if p.is_dir():
        raise UsageError(f"{option} {p}: is a directory, expected a file")
    if not os.access(p, os.R_OK):
        raise UsageError(f"{option} {p}: not readable by this user")
    return p


def check_input_path(path: str | Path, option: str = "input") -> Path:
    """A file or a directory that must exist and be readable."""
    p = Path(path)
    if not p.exists():
        raise UsageError(f"{option} {p}: no such file or directory")
    if not os.access(p, os.R_OK):
        raise UsageError(f"{option} {p}: not readable by this user")
    return p


def check_output_dir(path: str | Path, option: str = "--out") -> Path:
    """A directory to write into: an existing writable directory, or one that can be created
    (its nearest existing ancestor is a writable directory). Nothing is created here."""
    p = Path(path)
    if p.exists():
        if not p.is_dir():
            raise UsageError(f"{option} {p}: exists and is not a directory")
        if not os.access(p, os.W_OK | os.X_OK):
            raise UsageError(f"{option} {p}: directory not writable by this user")
        return p
    probe = _nearest_existing(p)
    if not probe.is_dir():
        raise UsageError(f"{option} {p}: cannot be created, {probe} is not a directory")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {p}: cannot be created, {probe} is not writable")
    return p


def check_output_file(path: str | Path, option: str = "--out") -> Path:
    """A file to write: not a directory, in an existing writable directory."""
    p = Path(path)
    if p.is_dir():
        raise UsageError(f"{option} {p}: is a directory, expected a file name")
    parent = p.absolute().parent
    if not parent.exists():
        raise UsageError(f"{option} {p}: directory {parent} does not exist")
    if not parent.is_dir():
        raise UsageError(f"{option} {p}: {parent} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {p}: directory {parent} not writable by this user")
    if p.exists() and not os.access(p, os.W_OK):
        raise UsageError(f"{option} {p}: exists and is not writable by this user")
    return p


# --------------------------------------------------------------------------- URLs


# --------------------------------------------------------------------------- numbers


def check_number(value: float, option: str, *, minimum: float | None = None,
                 above: float | None = None) -> float:
    """A finite number, ``>= minimum`` and/or ``> above``."""
    if not math.isfinite(value):
        raise UsageError(f"{option}: expected a finite number, found {value}")
    if minimum is not None and value < minimum:
        raise UsageError(f"{option}: expected a number >= {minimum:g}, found {value:g}")
    if above is not None and value <= above:
        raise UsageError(f"{option}: expected a number > {above:g}, found {value:g}")
    return value


# --------------------------------------------------------------------------- argparse types


def _as_type(check: Callable[[str], T], name: str) -> Callable[[str], T]:
    """A check as an ``argparse`` ``type=``: its message becomes argparse's (exit 2)."""

    def convert(text: str) -> T:
        try:
            return check(text)
        except UsageError as err:
            text = str(err).removeprefix("value").lstrip(": ")
            raise argparse.ArgumentTypeError(text) from None
        except OSError as err:  # EACCES: a directory on the path this user may not search
            raise argparse.ArgumentTypeError(os_error_text(text, err)) from None

    convert.__name__ = name  # argparse names the type in "invalid NAME value"
    return convert


def os_error_text(path: str, err: OSError) -> str:
    """``PATH: Permission denied (...)``: an OSError met while looking at a path, for a user."""
    hint = ""
    if isinstance(err, PermissionError):
        hint = (" (this user may not search a directory on the path, or read or write the "
                "file)")
    return f"{err.filename or path}: {err.strerror or err}{hint}"


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise UsageError(f"value: expected a number, found {text!r}") from None


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise UsageError(f"value: expected a whole number, found {text!r}") from None


def _positive_float(text: str) -> float:
    return check_number(_float(text), "value", above=0.0)


def _non_negative_float(text: str) -> float:
    return check_number(_float(text), "value", minimum=0.0)


def _positive_int(text: str) -> int:
    n = _int(text)
    check_number(n, "value", minimum=1)
    return n


def _non_negative_int(text: str) -> int:
    n = _int(text)
    check_number(n, "value", minimum=0)
    return n


def _seed_list(text: str) -> list[int]:
    """Seeds as ``1-5``, ``1,3`` or both (``1-3,8``): whole numbers, ranges low to high."""
    out: list[int] = []
    for part in (p.strip() for p in text.split(",")):
        lo, dash, hi = part.partition("-")
        try:
            a, b = int(lo), int(hi if dash else lo)
        except ValueError:
            raise UsageError(
                f"value: expected seeds like 1-5 or 1,3, found {text!r}") from None
        if b < a:
            raise UsageError(f"value: expected a range low to high, found {part!r}")
        out.extend(range(a, b + 1))
    return out


def _positive_float_list(text: str) -> list[float]:
    """Positive numbers, comma separated (``1,5,10``)."""
    parts = [p.strip() for p in text.split(",") if p.strip()]
    if not parts:
        raise UsageError(f"value: expected numbers like 1,5,10, found {text!r}")
    return [_positive_float(p) for p in parts]


def choice_list(choices: Sequence[str], name: str) -> Callable[[str], list[str]]:
    """An ``argparse`` type: names from ``choices``, comma separated, each checked."""

    def check(text: str) -> list[str]:
        names = [p.strip() for p in text.split(",") if p.strip()]
        bad = [n for n in names if n not in choices]
        if bad or not names:
            raise UsageError(f"value: expected {name} from {', '.join(choices)} (comma "
                             f"separated), found {text!r}")
        return names

    return _as_type(check, name)


positive_float = _as_type(_positive_float, "positive_float")
seed_list = _as_type(_seed_list, "seed_list")
positive_float_list = _as_type(_positive_float_list, "positive_float_list")
non_negative_float = _as_type(_non_negative_float, "non_negative_float")
positive_int = _as_type(_positive_int, "positive_int")
non_negative_int = _as_type(_non_negative_int, "non_negative_int")
input_file_arg = _as_type(lambda s: check_input_file(s, "value"), "input_file")
input_path_arg = _as_type(lambda s: check_input_path(s, "value"), "input_path")
output_dir_arg = _as_type(lambda s: check_output_dir(s, "value"), "output_dir")
output_file_arg = _as_type(lambda s: check_output_file(s, "value"), "output_file")
mavlink_url_arg = _as_type(lambda s: check_mavlink_url(s, "value"), "mavlink_url")
serial_url_arg = _as_type(lambda s: check_serial_url(s, "value", pty=False), "serial_url")
output_url_arg = _as_type(lambda s: check_serial_url(s, "value", pty=True), "output_url")
