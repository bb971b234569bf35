"""Which vehicle a config file describes, and running it on the one runtime.

:func:`run_file` is what ``fdi-bridge run`` and ``fdi-bridge mavlink`` (with a vehicle in the
file) do: the vehicle of the file (:func:`vehicle_from_file`), its flight recorder, the router
when there is a ``[mavlink]`` table, all on a :class:`~firmware_host.runtime.runner.Runner`
until a signal or the duration; the summary is logged at the end.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import tomllib
from pathlib import Path
from typing import Any, Literal

from drivers.configload import load_dataclass, read_toml
from fdi.errors import ConfigError
from firmware_host.mavlink.router import MavlinkConfig, load_vehicle_config
from firmware_host.rov.ardusub import ArduSubRovVehicle
from firmware_host.rov.config import RovConfig, load_rov_config
from firmware_host.rov.vehicle import OutlandRovVehicle
from firmware_host.rover.vehicle import RoverVehicle
from firmware_host.runtime.config import CONFIG_DIR, BridgeConfig, load_config
from firmware_host.runtime.recorder import FlightRecorder
from firmware_host.runtime.runner import Runner, make_recorder
from firmware_host.runtime.vehicle import Vehicle

log = logging.getLogger("fdi_bridge.run")

VehicleKind = Literal["rover", "rov"]


# --------------------------------------------------------------------------- which vehicle


def resolve_config_path(name: str | Path) -> Path:
    """A path, or a preset name (``rov``, ``rover-paper``) looked up in ``config/``."""
    p = Path(name)
    if not p.exists() and not p.suffix and (CONFIG_DIR / f"{p.name}.toml").exists():
        return CONFIG_DIR / f"{p.name}.toml"
    return p


def tables(path: str | Path) -> set[str]:
    try:
        with open(resolve_config_path(path), "rb") as fh:
            return {k for k, v in tomllib.load(fh).items() if isinstance(v, dict)}
    except (OSError, tomllib.TOMLDecodeError):
        return set()  # vehicle_of() reports it precisely


def vehicle_of(path: str | Path) -> VehicleKind:
    """``rover`` for a file with a ``[rover]`` table; ``rov`` for one with the ROV's own keys
    (``[link]``, ``[detector]``, ``[ft]``, ``[pid]``, ``period_s``, ``setpoint_deg`` ...; ``[sim]``
    and ``[recorder]`` are shared and do not count). Both or neither: a ConfigError."""
    p = resolve_config_path(path)
    try:
        with open(p, "rb") as fh:
            table = tomllib.load(fh)
    except FileNotFoundError as err:
        raise ConfigError(str(p), "(file)", "an existing TOML file", "no such file") from err
    except OSError as err:
        raise ConfigError(str(p), "(file)", "a readable TOML file", str(err.strerror)) from err
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(str(p), "(syntax)", "valid TOML", str(err)) from err
    rov_keys = {f.name for f in dataclasses.fields(RovConfig)} - {"sim", "recorder"}
    rover = isinstance(table.get("rover"), dict)
    rov = sorted(rov_keys & set(table))
    if rover and rov:
        raise ConfigError(str(p), ", ".join(["rover", *rov]),
                          "the keys of one vehicle: [rover] or the ROV's", "both")
    if not rover and not rov:
        raise ConfigError(str(p), "[rover] / [link]", "a [rover] table (rover) or the ROV's "
                          "keys ([link], [detector], period_s ...)", "neither")
    return "rover" if rover else "rov"


# --------------------------------------------------------------------------- vehicles


def load_rov(path: Path) -> tuple[RovConfig, Path]:
    """The ROV's config and its protocol directory; a ``[mavlink]`` table is the router's."""
    table = read_toml(path)
    if "mavlink" not in table:
        return load_rov_config(path)
    rest = {k: v for k, v in table.items() if k != "mavlink"}
    return load_dataclass(RovConfig, rest, str(path)), path.resolve().parent


def vehicle_from_file(
    path: Path, *, nmea_url: str | None = None, mavlink_url: str | None = None,
    record: Path | None = None, note: str = "fdi-bridge run",
) -> tuple[Vehicle, FlightRecorder | None]:
    """The vehicle the file describes and its flight recorder (``record`` overrides the
    ``[recorder]`` directory)."""
    kinds = tables(path)
    if vehicle_of(path) == "rover":
        cfg = load_vehicle_config(path) if "mavlink" in kinds else load_config(path)
        assert isinstance(cfg, BridgeConfig)
        rover = RoverVehicle(cfg, nmea_url=nmea_url, mavlink_url=mavlink_url)
        return rover, make_recorder(cfg.recorder, record, note)
    rcfg, base = load_rov(path)
    rov: Vehicle
    if "mavlink" in kinds and "link" not in kinds:
        rov = ArduSubRovVehicle(rcfg)
    else:
        rov = OutlandRovVehicle(rcfg, base)
    return rov, make_recorder(rcfg.recorder, record, note)


def run_file(
    path: Path, *, mavlink: MavlinkConfig | None, out: Path | None = None,
    record: Path | None = None, duration_s: float | None = None,
    nmea_url: str | None = None, mavlink_url: str | None = None, note: str = "fdi-bridge run",
) -> dict[str, Any]:
    """Run the vehicle of the file at ``path`` on the runtime until a signal or
    ``duration_s``; with ``mavlink``, behind the router. Returns the summary."""
    vehicle, recorder = vehicle_from_file(path, nmea_url=nmea_url, mavlink_url=mavlink_url,
                                          record=record, note=note)
    if mavlink is not None and mavlink_url:
        log.warning("--mavlink %s ignored: the [mavlink] router is the MAVLink output",
                    mavlink_url)
    runner = Runner(vehicle, out_dir=out, recorder=recorder, mavlink=mavlink,
                    duration_s=duration_s)
    summary = runner.run()
    log.info("summary %s", json.dumps(_brief(summary), separators=(",", ":")))
    return summary


def _brief(summary: dict[str, Any]) -> dict[str, Any]:
    """The journal's line at shutdown: what stopped it and the main counters."""
    keys = ("vehicle", "runtime", "epochs", "faults", "alarms", "steps", "overruns",
            "failsafe", "port", "shutdown")
    out = {k: summary[k] for k in keys if k in summary}
    rec = summary.get("recorder")
    if isinstance(rec, dict):
        out["recorder"] = {k: rec.get(k) for k in ("files_opened", "write_errors")}
    return out


