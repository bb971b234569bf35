"""The ROV on the Outland link as a vehicle of the runtime: 5 Hz heading hold with compass FDI.

Paced by its period (``"period"``, ``period_s``, absolute deadlines): each step takes the
newest telemetry from the link (RS-232 streaming, or an RS-485 poll by address), runs the
controller (:class:`~firmware_host.rov.control.RovController`: detector, substitution, PID,
the dropout rule), sends the thruster command and writes one record to ``epochs.jsonl``.
Failsafe: the controller holds the last command for ``dropout_hold_s`` without telemetry,
then neutral thrust; :class:`~firmware_host.rov.failsafe.RovFailsafeMonitor` counts the
episodes and says when telemetry is back. With a ``[mavlink]`` router, the operator gets the
corrected heading, the statistics and the events
(:class:`~firmware_host.rov.ardusub.RovOperatorSink`).

With a flight recorder, each step first writes one record on the ``rov tick`` channel
(:data:`TICK`, ``{"k": step, "t": seconds since start}``), so the link's bytes of a step lie
between its tick and the next one: ``fdi-bridge replay`` re-runs the steps with exactly those
bytes (:mod:`firmware_host.rov.replay`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from drivers.outland.framecodec import load_protocol
from drivers.outland.link import OutlandLink, Telemetry
from drivers.transport import SerialSettings
from firmware_host.rov.ardusub import RovOperatorSink
from firmware_host.rov.base import RovVehicleBase
from firmware_host.rov.config import RovConfig, protocol_path
from firmware_host.rov.control import RovController, epoch_record
from firmware_host.runtime.vehicle import Context, MavlinkSpec, PortSpec

LINK = "rov link"
TICK = "rov tick"  # the recorder channel of the step marks (docs/capture-format.md)
EpochCallback = Callable[[dict[str, Any]], None]


def link_step(
    link: OutlandLink, ctl: RovController, dt: float
) -> tuple[Telemetry | None, dict[str, Any]]:
    """One period on a live link: get the newest telemetry, run the controller, send."""
    tel: Telemetry | None
    if link.wiring == "rs485":
        tel = link.poll(ctl.command)
    else:
        got = link.read_telemetry()
        tel = got[-1] if got else None
    meas = None if tel is None else tel.heading_deg
    flagged = tel is not None and tel.heading_suspect
    cmd, dec = ctl.step(meas, dt, heading_suspect=flagged)
    if link.wiring == "rs232":
        link.send_command(cmd)
    return tel, epoch_record(0.0, None, meas, ctl.setpoint_deg, cmd, dec, ctl.action,
                             heading_suspect=flagged)


def link_settings(cfg: RovConfig) -> SerialSettings:
    """The link's port settings: RS-485 reads must not block past the reply timeout; RS-232
    reads take what is there."""
    s = cfg.link.port
    if cfg.link.wiring == "rs485":
        return replace(s, timeout_s=min(s.timeout_s, cfg.link.reply_timeout_s / 5))
    return replace(s, timeout_s=0.0)


class OutlandRovVehicle(RovVehicleBase):
    """See the module docstring. ``base_dir`` resolves a relative protocol path; the step
    marks, records, ``check``/``idle_s``/``finish`` and the summary's frame are
    :class:`~firmware_host.rov.base.RovVehicleBase`'s."""

    name = "rov"

    def __init__(self, cfg: RovConfig, base_dir: Path, *, ft: bool = True,
                 on_epoch: EpochCallback | None = None) -> None:
        super().__init__(cfg)
        self.proto = load_protocol(protocol_path(cfg, base_dir))  # a bad file fails here
        self.ft = ft
        self.on_epoch = on_epoch
        self.link: OutlandLink | None = None
        self.ctl = RovController(cfg, ft=ft)
        self.operator: RovOperatorSink | None = None

    def ports(self) -> list[PortSpec]:
        return [PortSpec(LINK, link_settings(self.cfg), self.cfg.link.reconnect_max_s,
                         record_rx=True, record_tx=True)]

    def mavlink(self) -> MavlinkSpec | None:
        return None  # the ROV speaks MAVLink only through a [mavlink] router

    def outputs(self) -> tuple[str, ...]:
        """No output besides MAVLink (the start banner)."""
        return ()

    def status_fields(self) -> dict[str, Any]:
        """Nothing beyond the runner's own status line fields."""
        return {}

    def status_detail(self) -> tuple[str, ...]:
        """Nothing after the ports on the status line."""
        return ()

    def start(self, ctx: Context) -> None:
        c = self.cfg.link
        self.link = OutlandLink(ctx.ports[LINK], self.proto, c.wiring, c.address,
                                c.reply_timeout_s, clock=ctx.clock)
        if ctx.mavlink is not None:
            self.operator = RovOperatorSink(ctx.mavlink)
        self.epochs = ctx.epochs
        self.tick = ctx.tap(TICK, "", 0, "tx")
        self.t0 = ctx.clock()

    def step(self, t: float) -> int:
        assert self.link is not None
        self._mark(t)  # before any read: the step's bytes follow its mark
        self.steps += 1
        _, rec = link_step(self.link, self.ctl, self.cfg.period_s)
        rec["t"] = round(t - self.t0, 3)
        self._account(rec)
        if self.operator is not None:
            self.operator(rec)
        if self.on_epoch is not None:
            self.on_epoch(rec)
        self.epochs.write(rec)
        return 1

    def _summary_fields(self) -> dict[str, Any]:
        if self.link is None:
            return {}
        return {"counts": dict(self.link.counts), "rejects": dict(self.link.rejects)}
