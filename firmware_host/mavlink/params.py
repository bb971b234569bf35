"""Detector thresholds as MAVLink parameters: a small thread-safe registry with callbacks.

:class:`ParamStore` holds named float parameters (MAVLink ``param_id``: at most 16 ASCII
characters, upper case by convention) with defaults, bounds and a one-line doc. The router
answers PARAM_REQUEST_LIST / READ / SET from it; the detectors read it (``get``) or subscribe
(``on_change``), so an operator's change in QGroundControl or MAVProxy takes effect at once.

Values set at run time are written back to a local override file (TOML, ``NAME = value`` under
``[params]``), atomically (temporary file + rename), and read again at the next start; the
override file holds only values that differ from the defaults.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import re
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drivers.configload import read_toml
from fdi.errors import ConfigError

log = logging.getLogger("fdi_bridge.params")

PARAM_ID_MAX = 16
_NAME = re.compile(r"^[A-Z0-9_]{1,16}$")

OnChange = Callable[[str, float], None]


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: name (<= 16 chars, ``[A-Z0-9_]``), default, bounds, doc.

    ``integer``: the value is a whole number (MAV_PARAM_TYPE_INT32 on the wire); a value set
    is rounded, and what is in force is what is echoed.
    """

    name: str
    default: float
    min: float = -math.inf
    max: float = math.inf
    doc: str = ""
    integer: bool = False

    def __post_init__(self) -> None:
        if not _NAME.match(self.name):
            raise ValueError(f"parameter name {self.name!r}: 1-16 characters of A-Z, 0-9, _")
        if not self.min <= self.default <= self.max:
            bounds = f"[{self.min}, {self.max}]"
            raise ValueError(f"{self.name}: default {self.default} outside {bounds}")


class ParamStore:
    """Thread-safe parameter registry (see the module docstring)."""

    def __init__(self, override_file: str | Path | None = None) -> None:
        self._lock = threading.RLock()
        self._specs: dict[str, ParamSpec] = {}
        self._values: dict[str, float] = {}
        self._callbacks: list[OnChange] = []
        self._override_file = Path(override_file) if override_file else None
        self._overrides: dict[str, float] = {}
        self.rejected = 0  # PARAM_SETs refused (unknown name, out of bounds, not finite)
        self.write_errors = 0  # failed writes of the override file (disk full, read-only)
        self._unsaved = False  # values in force that the override file does not hold yet
        if self._override_file is not None and self._override_file.exists():
            table = read_toml(self._override_file).get("params", {})
            if not isinstance(table, dict):
                raise ConfigError(str(self._override_file), "params", "a table", repr(table))
            for key, value in table.items():
                if isinstance(value, bool) or not isinstance(value, int | float):
                    file = str(self._override_file)
                    raise ConfigError(file, f"params.{key}", "a number", repr(value))
                self._overrides[str(key)] = float(value)

    # -- registration ---------------------------------------------------------------------

    def register(self, spec: ParamSpec) -> float:
        """Add ``spec``; its value is the override file's when it has a valid one."""
        with self._lock:
            if spec.name in self._specs:
                raise ValueError(f"parameter {spec.name} registered twice")
            self._specs[spec.name] = spec
            value = spec.default
            override = self._overrides.get(spec.name)
            if override is not None and spec.min <= override <= spec.max:
                value = override
            self._values[spec.name] = value
            return value

    def register_dataclass(self, prefix: str, obj: Any) -> dict[str, str]:
        """Register every int/float field of a (frozen) config dataclass as ``PREFIX_FIELD``.

        Bounds come from the field metadata (``ge``/``gt``/``le``/``lt``, as in
        :mod:`drivers.configload`; a strict bound becomes the next float inside it), the
        doc from ``metadata["doc"]``. A name longer than 16 characters is cut (trailing ``_``
        removed). Returns ``{field: param name}``; see :meth:`dataclass_view`.
        """
        if not dataclasses.is_dataclass(obj) or isinstance(obj, type):
            raise TypeError("register_dataclass needs a dataclass instance")
        names: dict[str, str] = {}
        for fld in dataclasses.fields(obj):
            value = getattr(obj, fld.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                continue
            name = f"{prefix}_{fld.name}".upper()[:PARAM_ID_MAX].rstrip("_")
            meta = fld.metadata
            lo = float(meta["ge"]) if "ge" in meta else -math.inf
            if "gt" in meta:
                lo = math.nextafter(float(meta["gt"]), math.inf)
            hi = float(meta["le"]) if "le" in meta else math.inf
            if "lt" in meta:
                hi = math.nextafter(float(meta["lt"]), -math.inf)
            integer = isinstance(value, int)
            if integer:  # whole-number bounds (a strict bound's nextafter rounded inwards)
                lo = float(math.ceil(lo)) if math.isfinite(lo) else lo
                hi = float(math.floor(hi)) if math.isfinite(hi) else hi
            self.register(ParamSpec(name, float(value), lo, hi, str(meta.get("doc", "")),
                                    integer))
            names[fld.name] = name
        return names

    def dataclass_view(self, obj: Any, names: dict[str, str]) -> Any:
        """``obj`` with the current parameter values (ints rounded) -- a detector's live config."""
        changes: dict[str, Any] = {}
        with self._lock:
            for fld, name in names.items():
                current = getattr(obj, fld)
                value = self._values[name]
                changes[fld] = round(value) if isinstance(current, int) else value
        return dataclasses.replace(obj, **changes)

    def on_change(self, callback: OnChange) -> None:
        """Call ``callback(name, value)`` after every accepted change (from the router thread)."""
        with self._lock:
            self._callbacks.append(callback)

    # -- access ---------------------------------------------------------------------------

    def get(self, name: str) -> float:
        with self._lock:
            return self._values[name]

    def names(self) -> list[str]:
        """Parameter names in registration order (their MAVLink ``param_index``)."""
        with self._lock:
            return list(self._specs)

    def index_of(self, name: str) -> int:
        with self._lock:
            return list(self._specs).index(name)

    def spec(self, name: str) -> ParamSpec:
        with self._lock:
            return self._specs[name]

    def __len__(self) -> int:
        return len(self._specs)

    def set(self, name: str, value: float) -> bool:
        """Set ``name`` to ``value``; False (and counted) when unknown, not finite or out of bounds.

        An accepted change is written to the override file and passed to the callbacks.
        """
        with self._lock:
            spec = self._specs.get(name)
            if spec is not None and spec.integer and math.isfinite(value):
                value = float(round(value))
            if spec is None or not math.isfinite(value) or not spec.min <= value <= spec.max:
                self.rejected += 1
                return False
            self._values[name] = float(value)
            if float(value) == spec.default:
                self._overrides.pop(name, None)
            else:
                self._overrides[name] = float(value)
            self._save()
            callbacks = list(self._callbacks)
        for cb in callbacks:
            cb(name, float(value))
        return True

    @property
    def unsaved(self) -> bool:
        """True while values in force are not in the override file (its last write failed)."""
        return self._unsaved

    def retry_save(self) -> bool:
        """Write the override file again after a failure; True when it is up to date."""
        with self._lock:
            if self._unsaved:
                self._save()
            return not self._unsaved

    def _save(self) -> None:
        """Write the override file; a full or read-only disk is logged once and counted, and
        the value stays in force (the router retries with :meth:`retry_save`)."""
        try:
            self._write_overrides()
        except OSError as err:
            self.write_errors += 1
            if not self._unsaved:
                log.warning("parameter file %s not written (%s); values stay in force and "
                            "the write is retried", self._override_file, err.strerror or err)
            self._unsaved = True
            return
        if self._unsaved:
            log.warning("parameter file %s written again", self._override_file)
        self._unsaved = False

    def _write_overrides(self) -> None:
        if self._override_file is None:
            return
        path = self._override_file
        lines = [
            "# fdi-bridge parameter overrides, written by the bridge when a ground station",
            "# sets a parameter. Delete a line to return to the default.",
            "[params]",
        ]
        lines += [f"{k} = {v!r}" for k, v in sorted(self._overrides.items())]
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write("\n".join(lines) + "\n")
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except OSError:
            Path(tmp).unlink(missing_ok=True)
            raise
