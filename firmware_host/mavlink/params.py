"""Detector thresholds as MAVLink parameters: a small thread-safe registry with callbacks.

:class:`ParamStore` holds named float parameters (MAVLink ``param_id``: at most 16 ASCII
characters, upper case by convention) with defaults, bounds and a one-line doc. The router
answers PARAM_REQUEST_LIST / READ / SET from it; the detectors read it (``get``) or subscribe
(``on_change``), so an operator's change in QGroundControl or MAVProxy takes effect at once.

Values set at run time are written back to a local override file (TOML, ``NAME = value`` under
``[params]``), atomically (temporary file + rename), and read again at the next start; the
override file holds only values that differ from the defaults.

One validation: a parameter registered from a config dataclass
(:meth:`ParamStore.register_dataclass`) is checked with the configuration loader's own bounds
(:func:`drivers.configload.check_number`, the field metadata) and the dataclass's own
cross-checks, so a PARAM_SET is refused exactly when a config file with that value would be.
A refused PARAM_SET changes nothing (the router answers with the value in force) and is
logged, rate-limited. The override file therefore never holds a value the loader would refuse;
one found there at start (an older bridge wrote it, a person edited it) is logged, naming the
file, the parameter, what was expected and what was found, and ignored: the configured value
is in force and the bridge starts. A file that is not TOML at all is ignored the same way and
kept as ``<file>.bad`` when a parameter is next written.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import re
import struct
import tempfile
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.configload import check_number, number_range, read_toml
from drivers.ratelog import RateLimitedLog
from fdi.errors import ConfigError

log = logging.getLogger("fdi_bridge.params")

PARAM_ID_MAX = 16
_NAME = re.compile(r"^[A-Z0-9_]{1,16}$")

OnChange = Callable[[str, float], None]


def _float32(value: float) -> float:
    """``value`` as MAVLink carries it (PARAM_SET.param_value is a float32)."""
    try:
        return float(struct.unpack("<f", struct.pack("<f", value))[0])
    except OverflowError:
        return math.copysign(math.inf, value)


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: name (<= 16 chars, ``[A-Z0-9_]``), default, bounds, doc.

    ``integer``: the value is a whole number (MAV_PARAM_TYPE_INT32 on the wire); a value set
    is rounded, and what is in force is what is echoed. ``off``: a value accepted beside
    ``[min, max]`` (a documented "off"). ``check``: the whole validation instead of the range
    (:meth:`ParamStore.register_dataclass` sets it to the loader's); it returns what was
    expected, or None.
    """

    name: str
    default: float
    min: float = -math.inf
    max: float = math.inf
    doc: str = ""
    integer: bool = False
    off: float | None = None
    check: Callable[[float], str | None] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if not _NAME.match(self.name):
            raise ValueError(f"parameter name {self.name!r}: 1-16 characters of A-Z, 0-9, _")
        why = self.refusal(self.default)
        if why is not None:
            raise ValueError(f"{self.name}: default {self.default}: expected {why}")

    def refusal(self, value: float) -> str | None:
        """What was expected when ``value`` (already rounded for an integer) is refused; None
        when it may be set."""
        if not math.isfinite(value):
            return "a finite number"
        if self.check is not None:
            return self.check(value)
        if self.off is not None and value == self.off:
            return None
        if not self.min <= value <= self.max:
            return f"a number >= {self.min:g} and <= {self.max:g}"
        return None


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
        self.ignored_overrides = 0  # values of the override file refused at start
        self._unsaved = False  # values in force that the override file does not hold yet
        self._keep_bad = False  # the file is not TOML: kept as <file>.bad at the next write
        self._refusals = RateLimitedLog(log)
        if self._override_file is not None:
            self._read_overrides(self._override_file)

    def _ignored(self, key: str, expected: str, found: str, in_force: str) -> None:
        """Report one value of the override file that is not used (module docstring)."""
        self.ignored_overrides += 1
        log.warning("parameter file %s: %s: expected %s, found %s; ignored, %s in force",
                    self._override_file, key, expected, found, in_force)

    def _read_overrides(self, path: Path) -> None:
        """Read the override file: what it holds that is not a number is reported, left out,
        and the file written again without it; a file that does not read is reported and
        ignored (module docstring). Never raises: a bad file must not stop the bridge."""
        try:
            data = read_toml(path)
        except ConfigError as err:
            if isinstance(err.__cause__, FileNotFoundError):
                return  # none yet: the defaults
            self._keep_bad = not isinstance(err.__cause__, OSError)
            self._ignored(err.key, err.expected, err.found, "the configured values")
            return
        table = data.get("params", {})
        if not isinstance(table, dict):
            self._keep_bad = True
            self._ignored("params", "a table", repr(table), "the configured values")
            return
        dropped = False
        for key, value in table.items():
            if (isinstance(value, bool) or not isinstance(value, int | float)
                    or not math.isfinite(value)):
                self._ignored(f"params.{key}", "a finite number", repr(value),
                              "its configured value")
                dropped = True
                continue
            self._overrides[str(key)] = float(value)
        if dropped:
            self._save()

    # -- registration ---------------------------------------------------------------------

    def register(self, spec: ParamSpec) -> float:
        """Add ``spec``; its value is the override file's when that passes ``spec``'s checks,
        else the default (the override is reported and removed from the file)."""
        with self._lock:
            if spec.name in self._specs:
                raise ValueError(f"parameter {spec.name} registered twice")
            self._specs[spec.name] = spec
            value = spec.default
            override = self._overrides.get(spec.name)
            if override is not None:
                if spec.integer:
                    override = float(round(override))
                why = spec.refusal(override)
                if why is None:
                    value = override
                else:
                    self._drop_override(spec, why, override)
            self._values[spec.name] = value
            return value

    def _drop_override(self, spec: ParamSpec, expected: str, found: float) -> None:
        self._ignored(spec.name, expected, repr(found), f"{spec.default!r} (the configured value)")
        self._overrides.pop(spec.name, None)
        self._save()

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
            integer = isinstance(value, int)
            lo, hi = number_range(meta, integer)
            off = meta.get("off")

            def check(v: float, key: str = fld.name, meta: Mapping[str, Any] = meta,
                      integer: bool = integer) -> str | None:
                why = check_number(round(v) if integer else v, meta, integer)
                return why if why is not None else self._group_refusal(obj, names, key, v)

            self.register(ParamSpec(name, float(value), lo, hi, str(meta.get("doc", "")),
                                    integer, None if off is None else float(off), check))
            names[fld.name] = name
        with self._lock:  # the file's values together: the dataclass's own cross-checks
            try:
                self.dataclass_view(obj, names)
            except (TypeError, ValueError, ArithmeticError) as err:
                for name in names.values():
                    if name in self._overrides:
                        spec = self._specs[name]
                        self._drop_override(spec, f"consistent values ({err})",
                                            self._values[name])
                        self._values[name] = spec.default
        return names

    def _group_refusal(self, obj: Any, names: dict[str, str], key: str,
                       value: float) -> str | None:
        """Why the dataclass ``obj`` with the values in force and ``key = value`` is refused
        by its own ``__post_init__``; None when it is not (or while it is being registered)."""
        with self._lock:
            if key not in names or not all(n in self._values for n in names.values()):
                return None  # registering: checked together once all are in
            current = {n: self._values[n] for n in names.values()}
            try:
                self._values[names[key]] = value
                self.dataclass_view(obj, names)
            except (TypeError, ValueError, ArithmeticError) as err:
                return f"consistent values ({err})"
            finally:
                self._values.update(current)
        return None

    def dataclass_view(self, obj: Any, names: dict[str, str]) -> Any:
        """``obj`` with the current parameter values (ints rounded) -- a detector's live config.
        Raises what the dataclass's ``__post_init__`` raises for an inconsistent set."""
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
        """Set ``name`` to ``value``; False (counted, logged rate-limited, nothing changed) when
        unknown or refused by its checks (module docstring).

        An accepted change is written to the override file and passed to the callbacks.
        """
        with self._lock:
            spec = self._specs.get(name)
            if spec is not None and spec.integer and math.isfinite(value):
                value = float(round(value))
            why = "a known parameter" if spec is None else spec.refusal(value)
            if why is not None and spec is not None and not spec.integer:
                # A bound sent by a ground station arrives as its float32 (0.01 ->
                # 0.0099999998): that is the bound, as the operator typed it.
                for bound in (spec.min, spec.max):
                    if math.isfinite(bound) and _float32(bound) == value:
                        value, why = bound, spec.refusal(bound)
            if why is not None:
                self.rejected += 1
                in_force = self._values.get(name)
                self._refusals.warning(
                    f"PARAM_SET {name}",
                    f"expected {why}, found {value!r}; refused, {in_force!r} stays in force")
                return False
            assert spec is not None
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
        if self._keep_bad:  # the unreadable file the bridge started with, for its owner
            os.replace(path, path.with_name(path.name + ".bad"))
            log.warning("parameter file %s kept as %s.bad", path, path.name)
            self._keep_bad = False
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
