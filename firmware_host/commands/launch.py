"""Which vehicle a config file describes, and running it on the one runtime.

:func:`run_file` is what ``fdi-bridge run`` and ``fdi-bridge mavlink`` (with a vehicle in the
file) do: the vehicle of the file (:func:`vehicle_from_file`), its flight recorder, the router
when there is a ``[mavlink]`` table, all on a :class:`~firmware_host.runtime.runner.Runner`
until a signal or the duration; the summary is logged at the end.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

from firmware_host.insgnss.vehicle import InsGnssVehicle
from firmware_host.mavlink.router import open_router
from firmware_host.rov.ardusub import ArduSubRovVehicle
from firmware_host.rov.vehicle import OutlandRovVehicle
from firmware_host.rover.vehicle import RoverVehicle
from firmware_host.runtime.config import BridgeFile, bridge_config, rov_config, vehicle_of
from firmware_host.runtime.config_mavlink import MavlinkConfig
from firmware_host.runtime.recorder import FlightRecorder
from firmware_host.runtime.runner import Runner, make_recorder
from firmware_host.runtime.status import StatusSink
from firmware_host.runtime.vehicle import Vehicle

log = logging.getLogger("fdi_bridge.run")


def vehicle_from_file(
    bf: BridgeFile, *, nmea_url: str | None = None, mavlink_url: str | None = None,
    record: Path | None = None, note: str = "fdi-bridge run",
) -> tuple[Vehicle, FlightRecorder | None]:
    """The vehicle the file describes (``[rover]``: the rover; ``[rover]`` and ``[insgnss]``:
    the live INS/GNSS; ``[rov]``: the ROV on the Outland link, or through an ArduSub autopilot
    with ``heading_source = "mavlink"`` and a ``[mavlink]`` table, checked at load) and its
    flight recorder (``record`` overrides the ``[recorder]`` directory)."""
    recorder = make_recorder(bf.recorder, record, note)
    if vehicle_of(bf) == "rover" and bf.insgnss is not None:  # [rover] + [insgnss]: live INS
        return InsGnssVehicle(bridge_config(bf), bf.insgnss, nmea_url=nmea_url,
                              mavlink_url=mavlink_url), recorder
    if vehicle_of(bf) == "rover":
        rover = RoverVehicle(bridge_config(bf), nmea_url=nmea_url, mavlink_url=mavlink_url)
        return rover, recorder
    rcfg, base = rov_config(bf)
    if rcfg.heading_source == "mavlink":
        return ArduSubRovVehicle(rcfg), recorder  # MANUAL_CONTROL from [mavlink] pilot_system_id
    return OutlandRovVehicle(rcfg, base), recorder


def run_file(
    bf: BridgeFile, *, mavlink: MavlinkConfig | None, out: Path | None = None,
    record: Path | None = None, duration_s: float | None = None,
    nmea_url: str | None = None, mavlink_url: str | None = None, note: str = "fdi-bridge run",
    status: StatusSink | None = None,
) -> dict[str, Any]:
    """Run the vehicle of the file on the runtime until a signal or ``duration_s``; with
    ``mavlink``, behind the router. Returns the summary."""
    vehicle, recorder = vehicle_from_file(bf, nmea_url=nmea_url, mavlink_url=mavlink_url,
                                          record=record, note=note)
    if mavlink is not None and mavlink_url:
        log.warning("--mavlink %s ignored: the [mavlink] router is the MAVLink output",
                    mavlink_url)
    runner = Runner(vehicle, out_dir=out, recorder=recorder, mavlink=mavlink,
                    open_router=open_router, duration_s=duration_s, status=status)
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


