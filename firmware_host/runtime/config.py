"""The bridge's configuration: one schema, one loader, the packaged presets.

One TOML file may hold any of ``[rover]`` (:class:`RoverConfig`), ``[rov]``
(:class:`~firmware_host.runtime.config_rov.RovConfig`), ``[insgnss]``
(:class:`~firmware_host.runtime.config_insgnss.InsGnssSetup`), ``[mavlink]``
(:class:`~firmware_host.runtime.config_mavlink.MavlinkConfig`) and ``[recorder]``
(:class:`~firmware_host.runtime.recorder.RecorderConfig`), beside ``name`` and ``description``.
:func:`load_bridge_file` reads it into a frozen :class:`BridgeFile` (a section the file does not
have is ``None``) and validates all of it (:mod:`drivers.configload`): a bad file fails at start
naming the file, the key, what was expected and what was found, every error of the file at once,
and the CLI exits with status 2. Beyond the types and bounds it refuses what would only fail
later: a significance level whose χ² threshold is not a finite number (``alpha = 5e-324``), a
protocol file that does not load (``scale = 0``), a URL the command line would refuse (a field
with ``metadata={"url": kind}``, :data:`URL_KINDS`: ``udpout:127.0.0.1:99999``, ``tcp://...``
for an NMEA output), named with the schemes that are accepted.

Every command reads its file here; the older functions (:func:`load_config`,
``firmware_host.rov.config.load_rov_config``, ``firmware_host.mavlink.router.load_mavlink_config``,
``firmware_host.devtools.insgnss_sim.load_setup``) are views of a :class:`BridgeFile`.

Names and files (:func:`resolve_config_path`): ``--config X`` is the file ``X`` when ``X`` is a
file (a directory named ``rov/`` is not); otherwise a bare name is a packaged preset
(``fdi-bridge presets``). The presets are ``config/*.toml`` in the repository and ship inside the
wheel as ``firmware_host/presets`` (:func:`presets_dir`). A protocol file named by ``[rov.link]
protocol`` is looked for beside the config file, then among the packaged ``protocols/``.

Older layouts still load, with one deprecation warning per file: the ROV's keys at the top level
(``period_s``, ``[link]``, ``[detector]``, ``[sim]`` ...) are read as ``[rov]``, and the INS/GNSS
file's top-level ``[filter]`` and ``[sim]`` as ``[insgnss]``.

``BridgeConfig()`` with no file is the rover's built-in default, which ``config/rover.toml``
states explicitly (a test keeps the two equal).
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib.util
import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from drivers.configload import load_dataclass, raise_all, read_toml, toml_fields
from drivers.mavlink.modes import alarm_mode
from drivers.outland.framecodec import load_protocol
from drivers.transport import SerialSettings
from drivers.urls import MAVLINK_SCHEMES, SERIAL_SCHEMES, check_mavlink_url, check_serial_url
from fdi.chi2 import threshold
from fdi.errors import ConfigError, UsageError
from fdi.rover import RoverDetectorParams
from fdi.three_zone import ThreeZoneParams
from firmware_host.runtime.config_insgnss import InsGnssSetup
from firmware_host.runtime.config_mavlink import MavlinkConfig
from firmware_host.runtime.config_rov import RovConfig, heading_source_errors
from firmware_host.runtime.recorder import RecorderConfig

log = logging.getLogger("fdi_bridge.config")

PRESETS_PACKAGE = "firmware_host.presets"
_REPO_CONFIG = Path(__file__).resolve().parents[2] / "config"


def presets_dir() -> Path:
    """The directory of the presets: the repository's ``config/`` in a source checkout (or an
    editable install), else the wheel's ``firmware_host/presets`` package data."""
    if (_REPO_CONFIG / "rover.toml").is_file():
        return _REPO_CONFIG
    spec = importlib.util.find_spec(PRESETS_PACKAGE)
    if spec is not None and spec.submodule_search_locations:
        for location in spec.submodule_search_locations:
            if (Path(location) / "rover.toml").is_file():
                return Path(location)
    return _REPO_CONFIG  # nothing packaged: names do not resolve, paths still do


CONFIG_DIR = presets_dir()


def preset_names() -> list[str]:
    return sorted(p.stem for p in presets_dir().glob("*.toml"))


def resolve_config_path(name: str | Path) -> Path:
    """``name`` when it is a file; else the packaged preset of that name (``rov``,
    ``rover-paper``, ``rov.toml``); else ``name`` itself when it looks like a path (the loader
    then says what is wrong with it). A bare name that is neither: a ConfigError."""
    p = Path(name).expanduser()
    if p.is_file():
        return p
    bare = p.parent == Path(".") and p.suffix in ("", ".toml")
    if bare:
        preset = presets_dir() / f"{p.stem}.toml"
        if preset.is_file():
            return preset
        if not p.exists():
            names = ", ".join(preset_names()) or "(none installed)"
            near = difflib.get_close_matches(p.stem, preset_names(), n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise ConfigError(str(name), "(file)", f"a TOML file or a preset name ({names})",
                              f"no such file or preset{hint}")
    return p


def resolve_protocol(protocol: str | Path, base: Path | None) -> Path:
    """A protocol file: absolute as given, else beside the config (``base``), else packaged."""
    p = Path(protocol).expanduser()
    if p.is_absolute():
        return p
    if base is not None and (base / p).is_file():
        return base / p
    packaged = presets_dir() / p
    if packaged.is_file():
        return packaged
    if p.parent == Path("."):
        packaged = presets_dir() / "protocols" / p
        if packaged.is_file():
            return packaged
    return (base or presets_dir()) / p  # missing: the protocol loader names it


# --------------------------------------------------------------------------- the rover


@dataclass(frozen=True)
class ReferencePoint:
    """The local frame's origin; without it, the first valid fix."""

    lat_deg: float = field(default=0.0, metadata={
        "ge": -90.0, "le": 90.0, "unit": "deg",
        "doc": "latitude of the local frame's origin (WGS-84)"})
    lon_deg: float = field(default=0.0, metadata={
        "ge": -180.0, "le": 180.0, "unit": "deg", "doc": "longitude of the origin"})
    alt_m: float = field(default=0.0, metadata={
        "ge": -12000.0, "le": 100000.0, "unit": "m", "doc": "ellipsoidal height of the origin"})


@dataclass(frozen=True)
class RoverOutputs:
    """Where corrected data goes. URLs are pyserial URLs; ``pty:PATH`` makes a pty, linked."""

    nmea_url: str = field(default="", metadata={
        "url": "nmea_out", "doc": "where the corrected NMEA goes: a serial device, a pyserial "
                                  "URL or pty:PATH (a pty made and linked at PATH); empty: none"})
    nmea_baudrate: int = field(default=9600, metadata={
        "gt": 0, "unit": "baud", "doc": "line speed of a serial nmea_url"})
    # e.g. "udpout:127.0.0.1:14550", or a serial device (reopened if lost)
    mavlink_url: str = field(default="", metadata={
        "url": "mavlink_out", "doc": "where GPS_INPUT goes (e.g. udpout:127.0.0.1:14550, or a "
                                     "serial device, reopened if lost); empty: none"})
    mavlink_baudrate: int = field(default=57600, metadata={
        "gt": 0, "unit": "baud", "doc": "line speed of a serial mavlink_url"})
    mavlink_system: int = field(default=1, metadata={
        "ge": 1, "le": 255, "unit": "-", "doc": "the bridge's MAVLink system id"})
    mavlink_component: int = field(default=191, metadata={
        "ge": 1, "le": 255, "unit": "-", "doc": "the bridge's MAVLink component id"})
    target_system: int = field(default=1, metadata={
        "ge": 1, "le": 255, "unit": "-",
        "doc": "the autopilot's system id (the mode request on an alarm)"})
    hold_on_alarm: bool = field(default=True, metadata={
        "doc": "on an alarm, ask the autopilot for alarm_mode"})
    vehicle: str = field(default="rover", metadata={
        "choices": ["rover", "boat", "sub", "copter", "plane"],
        "doc": "ArduPilot's vehicle, whose mode table names alarm_mode"})
    # Mode requested on an alarm; "" = the vehicle's default (rover HOLD, sub ALT_HOLD; copter
    # and plane must name one). Checked at load (drivers.mavlink.modes.alarm_mode).
    alarm_mode: str = field(default="", metadata={
        "range": "a mode of the vehicle's table, or \"\"",
        "doc": "mode requested on an alarm; empty: the vehicle's default (rover HOLD, sub "
               "ALT_HOLD; copter and plane must name one); checked at load"})
    gps_id: int = field(default=0, metadata={
        "ge": 0, "le": 1, "doc": "GPS_INPUT gps_id: 1 = GPS2", "unit": "-"})
    # Accuracy reported with a replaced fix is the prediction's, raised by this factor.
    replaced_accuracy_factor: float = field(default=3.0, metadata={
        "ge": 1.0, "le": 1000.0, "unit": "-",
        "doc": "the accuracy reported with a replaced fix is the prediction's, raised by this "
               "factor"})

    def __post_init__(self) -> None:
        if self.hold_on_alarm:
            alarm_mode(self.vehicle, self.alarm_mode)  # ValueError names what is allowed


@dataclass(frozen=True)
class RoverConfig:
    """The rover: the GNSS receiver's port, the detector, the outputs (the ``[rover]`` table)."""

    port: SerialSettings = field(
        default_factory=lambda: SerialSettings(url="/dev/ttyUSB0", baudrate=9600)
    )
    detector: RoverDetectorParams = field(default_factory=RoverDetectorParams)
    reference: ReferencePoint | None = None
    output: RoverOutputs = field(default_factory=RoverOutputs)
    max_line: int = field(default=120, metadata={
        "ge": 82, "le": 4096, "unit": "bytes",
        "doc": "longest NMEA sentence taken; a longer line is dropped and counted"})
    silence_s: float = field(default=2.0, metadata={
        "ge": 0.1, "le": 3600.0, "unit": "s",
        "doc": "no valid fix this long: the failsafe (a no-fix GPS_INPUT and a STATUSTEXT)"})
    reconnect_max_s: float = field(default=5.0, metadata={
        "ge": 0.1, "le": 3600.0, "unit": "s", "doc": "longest wait between reopens of a lost port"})


@dataclass(frozen=True)
class BridgeConfig:
    """The rover's view of a file (what the rover's commands take)."""

    name: str = "rover-default"
    description: str = ""
    rover: RoverConfig = field(default_factory=RoverConfig)
    recorder: RecorderConfig = field(default_factory=RecorderConfig)


# --------------------------------------------------------------------------- the file


@dataclass(frozen=True)
class BridgeFile:
    """A whole configuration file; a section it does not have is ``None``."""

    name: str = field(default="", metadata={
        "range": "any text", "doc": "the configuration's name, shown in the banner and the "
                                    "summary"})
    description: str = field(default="", metadata={
        "range": "any text", "doc": "one line about it (fdi-bridge presets lists it)"})
    rover: RoverConfig | None = None
    rov: RovConfig | None = None
    insgnss: InsGnssSetup | None = None
    mavlink: MavlinkConfig | None = None
    recorder: RecorderConfig = field(default_factory=RecorderConfig)
    path: Path | None = field(default=None, metadata={"toml": False})  # None: built-in defaults

    @property
    def base_dir(self) -> Path:
        """The directory relative paths of the file (protocols) start from."""
        return self.path.resolve().parent if self.path is not None else presets_dir()

    @property
    def sections(self) -> tuple[str, ...]:
        return tuple(s for s in ("rover", "rov", "insgnss", "mavlink")
                     if getattr(self, s) is not None)


_ROV_KEYS = frozenset(toml_fields(RovConfig)) - {"sim"}
_warned: set[str] = set()


def _deprecated(path: str, what: str) -> None:
    if path in _warned:
        return
    _warned.add(path)
    log.warning("%s: %s (deprecated layout: still read, please move them)", path, what)


def _migrate(table: dict[str, Any], file: str) -> dict[str, Any]:
    """The older layouts (module docstring) as the current one."""
    flat_rov = sorted(_ROV_KEYS & set(table))
    flat_ins = "filter" in table
    if not flat_rov and not flat_ins:
        return table
    if flat_rov and flat_ins:
        raise ConfigError(file, ", ".join([*flat_rov, "filter"]), "the top-level keys of one "
                          "older layout (the ROV's or the INS/GNSS's), better [rov] / [insgnss]",
                          "both")
    section = "rov" if flat_rov else "insgnss"
    moved = flat_rov if flat_rov else ["filter"]
    if "sim" in table:
        moved = [*moved, "sim"]
    if section in table:
        raise ConfigError(file, ", ".join(moved), f"these keys inside [{section}]",
                          f"both [{section}] and top-level keys")
    out = {k: v for k, v in table.items() if k not in moved}
    out[section] = {k: table[k] for k in moved}
    _deprecated(file, f"the {'ROV' if flat_rov else 'INS/GNSS'}'s keys at the top level "
                f"({', '.join(moved)}) belong in [{section}]")
    return out


def _walk(obj: Any, prefix: str) -> Iterator[tuple[str, Any]]:
    yield prefix, obj
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for f in dataclasses.fields(obj):
            yield from _walk(getattr(obj, f.name), f"{prefix}.{f.name}" if prefix else f.name)
    elif isinstance(obj, tuple):
        for i, item in enumerate(obj):
            if dataclasses.is_dataclass(item):
                yield from _walk(item, f"{prefix}[{i}]")


_SERIAL = ("a device path or a pyserial URL ("
           + ", ".join(f"{s}://" for s in SERIAL_SCHEMES) + ")")
_MAVLINK = ("a MAVLink URL (" + ", ".join(f"{s}:" for s in MAVLINK_SCHEMES)
            + " HOST:PORT, port 1-65535) or " + _SERIAL)
URL_KINDS: dict[str, str] = {
    "serial": _SERIAL,
    "imu": '"router", "" (none) or ' + _SERIAL,
    "nmea_out": '"" (none), pty:PATH or ' + _SERIAL,
    "mavlink": _MAVLINK,
    "mavlink_out": '"" (none) or ' + _MAVLINK,
}
"""What a URL field (``metadata={"url": kind}``) accepts; checked at load with the command
line's own checks (:mod:`drivers.urls`), the spelling only (a port is opened
when the bridge runs, a pty's directory is checked by the command that makes it)."""

# SerialSettings (drivers/transport.py) is the drivers' own; its url is a port to read.
_URL_FIELDS_ELSEWHERE: dict[tuple[type, str], str] = {(SerialSettings, "url"): "serial"}


def _url_refusal(url: str, kind: str) -> str | None:
    """Why ``url`` is not a URL of ``kind``; None when it is."""
    if kind in ("imu", "nmea_out", "mavlink_out") and url == "":
        return None
    if kind == "imu" and url == "router":
        return None
    if kind == "nmea_out" and url.startswith("pty:"):
        return None
    try:
        if kind in ("mavlink", "mavlink_out"):
            check_mavlink_url(url, "value")
        else:
            check_serial_url(url, "value", pty=False)
    except UsageError as err:
        why = str(err).removeprefix(f"value {url}: ").removeprefix("value: ")
        return why.split(" (known: ")[0].split(" (a MAVLink URL is ")[0]  # listed as expected
    return None


def _url_errors(bf: BridgeFile, file: str) -> list[ConfigError]:
    """Every URL of the file spelled as the command line would take it (:data:`URL_KINDS`)."""
    errors: list[ConfigError] = []
    for key, obj in _walk(bf, ""):
        if not dataclasses.is_dataclass(obj) or isinstance(obj, type):
            continue
        for f in dataclasses.fields(obj):
            kind = f.metadata.get("url") or _URL_FIELDS_ELSEWHERE.get((type(obj), f.name))
            url = getattr(obj, f.name)
            if kind is None or not isinstance(url, str):
                continue
            why = _url_refusal(url, kind)
            if why is not None:
                errors.append(ConfigError(file, f"{key}.{f.name}", URL_KINDS[kind],
                                          f"{url!r} ({why})"))
    return errors


def _derived_errors(bf: BridgeFile, file: str) -> list[ConfigError]:
    """Values inside their bounds whose derived quantity is not usable (module docstring)."""
    errors: list[ConfigError] = []

    def finite(key: str, value: float, compute: Any, what: str) -> None:
        try:
            ok = math.isfinite(compute())
        except (ValueError, ArithmeticError):
            ok = False
        if not ok:
            errors.append(ConfigError(file, key, what, f"{value!r} (float)"))

    probability = "a significance level whose threshold is a finite number (>= 1e-15)"
    for key, obj in _walk(bf, ""):
        if isinstance(obj, RoverDetectorParams):
            finite(f"{key}.alpha", obj.alpha, lambda o=obj: threshold(o.alpha, 3), probability)
        elif isinstance(obj, ThreeZoneParams):
            finite(f"{key}.alpha1", obj.alpha1, lambda o=obj: threshold(o.alpha1, 1), probability)
            finite(f"{key}.alpha2", obj.alpha2, lambda o=obj: threshold(o.alpha2, 1), probability)
    return errors


def parse_bridge_file(table: dict[str, Any], file: str, path: Path | None = None) -> BridgeFile:
    """A :class:`BridgeFile` from a TOML table already read (``file`` names it in errors)."""
    bf = load_dataclass(BridgeFile, _migrate(table, file), file)
    bf = dataclasses.replace(bf, path=path)
    raise_all(_derived_errors(bf, file) + _url_errors(bf, file)
              + heading_source_errors(bf.rov, bf.mavlink is not None, file))
    if bf.rov is not None:
        proto = resolve_protocol(bf.rov.link.protocol, bf.base_dir if path else None)
        load_protocol(proto)  # a protocol that does not load fails now, not at the first frame
        link = dataclasses.replace(bf.rov.link, protocol=str(proto))
        bf = dataclasses.replace(bf, rov=dataclasses.replace(bf.rov, link=link,
                                                               recorder=bf.recorder))
    return bf


def load_bridge_file(path: str | Path | None) -> BridgeFile:
    """Read and validate a configuration file (a path or a preset name); ``None``: an empty
    file (every section absent, the defaults of each view)."""
    if path is None:
        return BridgeFile()
    p = resolve_config_path(path)
    return parse_bridge_file(read_toml(p), str(p), p)


Vehicle = Literal["rover", "rov"]


def vehicle_of(config: str | Path | BridgeFile) -> Vehicle:
    """The vehicle ``fdi-bridge run`` runs for a file: ``rover`` with ``[rover]``, ``rov`` with
    ``[rov]``. Both or neither: a ConfigError."""
    bf = config if isinstance(config, BridgeFile) else load_bridge_file(config)
    file = str(bf.path) if bf.path is not None else "(built-in defaults)"
    if bf.rover is not None and bf.rov is not None:
        raise ConfigError(file, "rover, rov", "the table of one vehicle: [rover] or [rov]",
                          "both")
    if bf.rover is not None:
        return "rover"
    if bf.rov is not None:
        return "rov"
    found = "neither"
    if bf.insgnss is not None:
        found += " (an [insgnss] file: fdi-bridge sim insgnss --config FILE runs it)"
    raise ConfigError(file, "[rover] / [rov]", "a [rover] table (the rover) or an [rov] table "
                      "(the ROV)", found)


def run_mode(bf: BridgeFile) -> Literal["mavlink", "rover", "rov"]:
    """What ``fdi-bridge run`` does with a file: the router (``[mavlink]``, with the rover when
    the file has ``[rover]``), else the vehicle of :func:`vehicle_of` (errors as it)."""
    return "mavlink" if bf.mavlink is not None else vehicle_of(bf)


# --------------------------------------------------------------------------- the views


def bridge_config(bf: BridgeFile) -> BridgeConfig:
    """The rover's view; a file for another vehicle only is an error."""
    if bf.rover is None and (bf.rov is not None or bf.insgnss is not None):
        raise ConfigError(str(bf.path), "rover", "a [rover] table",
                          f"a file for {' and '.join(bf.sections)} only")
    default = BridgeConfig()
    return BridgeConfig(name=bf.name or default.name, description=bf.description,
                        rover=bf.rover if bf.rover is not None else default.rover,
                        recorder=bf.recorder)


def load_config(path: str | Path | None) -> BridgeConfig:
    """The rover's configuration in a file or preset; ``None`` gives the built-in defaults."""
    return bridge_config(load_bridge_file(path))


def rov_config(bf: BridgeFile) -> tuple[RovConfig, Path]:
    """The ROV's view and the directory its relative paths start from."""
    if bf.rov is not None:
        return bf.rov, bf.base_dir
    if bf.path is None:  # no file: the built-in defaults, with the packaged protocol
        defaults = parse_bridge_file({"rov": {}}, "(built-in defaults)")
        assert defaults.rov is not None
        return defaults.rov, presets_dir()
    raise ConfigError(str(bf.path), "rov", "an [rov] table",
                      f"a file for {' and '.join(bf.sections) or 'no vehicle'}")


def mavlink_config(bf: BridgeFile) -> MavlinkConfig:
    """The router's view (its defaults when the file has no ``[mavlink]``)."""
    return bf.mavlink if bf.mavlink is not None else MavlinkConfig()


def insgnss_setup(bf: BridgeFile) -> InsGnssSetup:
    """The INS/GNSS view (its defaults when the file has no ``[insgnss]``)."""
    return bf.insgnss if bf.insgnss is not None else InsGnssSetup()
