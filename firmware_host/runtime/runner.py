"""The one runtime: a :class:`Runner` runs any :class:`~firmware_host.runtime.vehicle.Vehicle`.

The runner owns, once for every vehicle and every mode:

* **signals**: SIGINT and SIGTERM (systemd's stop) end the loop cleanly: the vehicle finishes
  (its records completed, nothing stale sent), the ports, the MAVLink output and the router
  (its ``.tlog``) are closed, the flight recorder is flushed and fsynced, ``epochs.jsonl`` is
  closed and ``summary.json`` written; the command then exits 0;
* **time**: ``duration_s`` and the pacing on an injected clock (``clock``/``sleep``; tests pass
  a :class:`~firmware_host.runtime.loop.FakeClock`): ``"period"`` vehicles step on absolute
  deadlines (:class:`~firmware_host.runtime.loop.FixedRateLoop`, overruns counted), ``"data"``
  vehicles step as their input arrives;
* **ports**: each :class:`~firmware_host.runtime.vehicle.PortSpec` opened as a
  :class:`~drivers.resilient.ResilientPort` (a lost device reported once and reopened with
  backoff capped at the vehicle's ``reconnect_max_s``), with the recorder's taps on each
  direction it keeps;
* **outputs**: the MAVLink output built in one place (:mod:`firmware_host.runtime.mavout`):
  through the router when the config has ``[mavlink]`` (the router is started, attached and
  closed here), else from the vehicle's own URL, tapped into the recorder;
* **files**: ``epochs.jsonl`` and ``summary.json`` (:mod:`firmware_host.runtime.records`):
  the records handed to the kernel every 0.25 s (a ``SIGKILL`` loses at most that), a full or
  read-only disk logged once, counted (``epochs_file`` in the summary) and retried while
  detection and the outputs go on, ``summary.json`` written whole or not at all;
* **failsafes**: the vehicle's ``check`` (silence watchdogs) on every iteration, whatever the
  input does;
* **status**: with a ``status`` sink (:mod:`firmware_host.runtime.status`), a
  :class:`~firmware_host.runtime.status.Banner` once everything is open and a
  :class:`~firmware_host.runtime.status.Snapshot` every ``status_period_s`` (epochs, faults,
  alarms, each port's state and byte rate, the last record's age); the runner prints nothing.

``run()`` is ``start()``, the paced loop, ``close()``. The soak drives two runners by hand on
one fake clock with ``start``/``step``/``close``.
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any, Literal, TextIO

from drivers.capture import Channel
from drivers.resilient import Opener, ResilientPort
from drivers.transport import SerialSettings
from firmware_host.runtime import autopilot_echo
from firmware_host.runtime.config_mavlink import MavlinkConfig
from firmware_host.runtime.loop import FixedRateLoop
from firmware_host.runtime.mavout import (
    MavlinkOutput,
    RouterPort,
    open_mavlink_output,
    router_output,
)
from firmware_host.runtime.recorder import FlightRecorder, RecorderConfig
from firmware_host.runtime.records import EpochLog
from firmware_host.runtime.status import Banner, PortInfo, PortStatus, Snapshot, StatusSink
from firmware_host.runtime.vehicle import Context, PortSpec, Tap, Vehicle

log = logging.getLogger("fdi_bridge.runner")

Clock = Callable[[], float]
Sleep = Callable[[float], None]


def make_recorder(cfg: RecorderConfig, override: Path | None, note: str) -> FlightRecorder | None:
    """The flight recorder of ``[recorder]`` (``--record DIR`` wins), or None when no directory
    is configured."""
    directory = str(override) if override is not None else cfg.dir
    if not directory:
        return None
    return FlightRecorder(directory, cfg, note=note, background_sync=True)


def _channel(name: str, url: str, baud: int, direction: Literal["rx", "tx"],
             s: SerialSettings | None = None) -> Channel:
    if s is None:
        return Channel(name=name, url=url, baudrate=baud, direction=direction)
    return Channel(name=name, url=s.url, baudrate=s.baudrate, bytesize=s.bytesize,
                   parity=s.parity, stopbits=s.stopbits, direction=direction)


class Runner:
    """Runs one vehicle (see the module docstring).

    ``mavlink`` (the ``[mavlink]`` table) makes the runner open a router with ``open_router``
    (:func:`firmware_host.mavlink.router.open_router`: the runtime knows the router only as a
    :class:`~firmware_host.runtime.mavout.RouterPort`), start it and hand the vehicle its
    output; ``router`` hands it an existing one instead (the runner does not close it).
    ``mavlink_output`` replaces the vehicle's own MAVLink output (the soak's packer).
    ``opener`` replaces every port's opener (simulated devices). ``jsonl`` is an open stream
    for the records instead of ``out_dir/epochs.jsonl``.
    """

    def __init__(
        self,
        vehicle: Vehicle,
        *,
        out_dir: Path | None = None,
        jsonl: TextIO | None = None,
        recorder: FlightRecorder | None = None,
        own_recorder: bool = True,
        mavlink: MavlinkConfig | None = None,
        open_router: Callable[[MavlinkConfig], RouterPort] | None = None,
        router: RouterPort | None = None,
        mavlink_output: MavlinkOutput | None = None,
        duration_s: float | None = None,
        clock: Clock = time.monotonic,
        sleep: Sleep | None = None,
        opener: Opener | None = None,
        handle_signals: bool = True,
        status: StatusSink | None = None,
        status_period_s: float = 1.0,
    ) -> None:
        self.vehicle = vehicle
        self.out_dir = out_dir
        self.recorder = recorder
        self.own_recorder = own_recorder
        self.mavlink_cfg = mavlink
        if mavlink is not None and router is None and open_router is None:
            raise ValueError("a [mavlink] table needs open_router "
                             "(firmware_host.mavlink.router.open_router) or a router")
        self.open_router = open_router
        self.router = router
        self._own_router = False
        self.mavlink_output = mavlink_output
        self._own_output = False
        self.duration_s = duration_s
        self.clock = clock
        self._stop = threading.Event()
        self.sleep: Sleep = sleep if sleep is not None else self._wait
        self.opener = opener
        self.handle_signals = handle_signals
        self.ports: dict[str, ResilientPort] = {}
        self.epochs = EpochLog(None, stream=jsonl)
        self.loop: FixedRateLoop | None = None
        self.iterations = 0
        self.stopped_by = ""
        self._deadline: float | None = None
        self._started = False
        self._closed = False
        self._summary: dict[str, Any] = {}
        self.t0 = 0.0
        self.status = status
        self.status_period_s = status_period_s
        self.records = 0
        self._last_record_t: float | None = None
        self._next_status = 0.0
        self._status_prev: tuple[float, dict[str, tuple[int, int]]] | None = None
        self._echo: autopilot_echo.AutopilotEcho | None = None

    # ------------------------------------------------------------------ control

    def _wait(self, seconds: float) -> None:
        """The default sleep: ends early when a stop is asked for."""
        self._stop.wait(seconds)

    def stop(self, reason: str = "stop") -> None:
        """Ask the loop to end (thread- and signal-safe); the first reason is kept."""
        if not self.stopped_by:
            self.stopped_by = reason
        self._stop.set()

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        log.warning("%s: stopping", name)
        self.stop(name)

    def _should_stop(self, max_steps: int | None,
                     until: Callable[[], bool] | None = None) -> bool:
        if self._stop.is_set():
            return True
        if until is not None and until():
            self.stop("until")
            return True
        if self._deadline is not None and self.clock() >= self._deadline:
            self.stop("duration")
            return True
        if max_steps is not None and self.iterations >= max_steps:
            self.stop("max_steps")
            return True
        return False

    # ------------------------------------------------------------------ start / step / close

    def _tap(self, name: str, url: str, baud: int, direction: Literal["rx", "tx"],
             settings: SerialSettings | None = None) -> Tap | None:
        rec = self.recorder
        if rec is None:
            return None
        return rec.tap(rec.add_channel(_channel(name, url, baud, direction, settings)))

    def _open_port(self, spec: PortSpec) -> ResilientPort:
        s = spec.settings
        rx = self._tap(f"{spec.name} rx", s.url, s.baudrate, "rx", s) if spec.record_rx else None
        tx = self._tap(f"{spec.name} tx", s.url, s.baudrate, "tx", s) if spec.record_tx else None
        return ResilientPort(s, name=spec.name, backoff_max_s=spec.backoff_max_s,
                             clock=self.clock, opener=self.opener or spec.opener,
                             on_rx=rx, on_tx=tx)

    def start(self) -> None:
        """Open the router, the ports and the outputs; start the vehicle."""
        if self._started:
            return
        self._started = True
        self.t0 = self.clock()
        if self.duration_s is not None:
            self._deadline = self.t0 + self.duration_s
        if self.out_dir is not None:  # a full or read-only disk never stops the run
            self.epochs = EpochLog(self.out_dir, keep_going=True, clock=self.clock)
        v = self.vehicle
        if self.router is None and self.mavlink_cfg is not None and self.open_router is not None:
            cfg = self.mavlink_cfg
            self.router = self.open_router(cfg)
            self._own_router = True
            log.info("routing %s <-> %s", cfg.autopilot.url, ", ".join(g.url for g in cfg.gcs))
        for spec in v.ports():  # the ports' channels first: replay takes the first rx channel
            self.ports[spec.name] = self._open_port(spec)
        output = self.mavlink_output
        if output is None and self.router is not None:
            output = router_output(self.router)
        elif output is None:
            mav = v.mavlink()
            if mav is not None:
                tap = self._tap("mavlink tx", mav.url, mav.baudrate, "tx")
                output = open_mavlink_output(
                    mav.url, source_system=mav.source_system,
                    source_component=mav.source_component, baudrate=mav.baudrate,
                    backoff_max_s=mav.backoff_max_s, clock=self.clock, tap=tap,
                    **({"opener": self.opener} if self.opener is not None else {}))
                self._own_output = True
        self.mavlink_output = output
        if output is not None:  # the status line's autopilot (read at each snapshot)
            self._echo = autopilot_echo.attach(output, self.router, self.clock)
        ctx = Context(clock=self.clock, ports=self.ports, epochs=self.epochs, mavlink=output,
                      router=self.router,
                      tap=lambda name, url, baud, direction: self._tap(name, url, baud,
                                                                       direction))
        v.start(ctx)
        if self._own_router and self.router is not None:
            self.router.start()
        if self.status is not None:
            self.status.banner(self.banner())
            self._next_status = self.t0 + self.status_period_s

    def step(self, t: float | None = None) -> int:
        """One iteration: the vehicle's step (at ``t``, default now), its failsafes, the
        recorder's flush when due."""
        self.iterations += 1
        n = self.vehicle.step(self.clock() if t is None else t)
        now = self.clock()
        if n > 0:
            self.records += n
            self._last_record_t = now
        self.vehicle.check(now)
        self.epochs.poll(now)
        if self.recorder is not None:
            self.recorder.poll()
        if self.status is not None and now >= self._next_status:
            self._next_status = now + self.status_period_s
            self.status.update(self.snapshot(now))
        return n

    # ------------------------------------------------------------------ status

    def banner(self) -> Banner:
        """What is open: the vehicle, its ports, its outputs, the recorder, the router."""
        v = self.vehicle
        ports = tuple(PortInfo(name, p.settings.url, p.settings.baudrate)
                      for name, p in self.ports.items())
        outputs: list[str] = list(v.outputs())
        router: list[str] = []
        if self.router is not None and self.mavlink_cfg is not None:
            cfg = self.mavlink_cfg
            outputs.append("MAVLink through the router")
            router.append(f"autopilot {cfg.autopilot.url}")
            router += [f"gcs {g.url}" for g in cfg.gcs]
            if cfg.tlog_dir:
                router.append(f"tlog {cfg.tlog_dir}")
        elif self.router is not None:
            outputs.append("MAVLink through the router")
        elif self._own_output:
            mav = v.mavlink()
            if mav is not None:
                outputs.append(f"MAVLink {mav.url}")
        elif self.mavlink_output is not None:
            outputs.append("MAVLink (the caller's output)")
        rec = self.recorder
        return Banner(vehicle=v.name, ports=ports, outputs=tuple(outputs),
                      recorder=None if rec is None else str(rec.dir),
                      router=tuple(router),
                      out_dir=None if self.out_dir is None else str(self.out_dir),
                      duration_s=self.duration_s)

    def snapshot(self, now: float | None = None) -> Snapshot:
        """The live status now; byte rates since the previous snapshot."""
        now = self.clock() if now is None else now
        counts = {name: (p.bytes_rx, p.bytes_tx) for name, p in self.ports.items()}
        prev_t, prev = self._status_prev if self._status_prev is not None else (self.t0, {})
        dt = max(now - prev_t, 1e-9)
        ports = []
        for name, p in self.ports.items():
            rx0, tx0 = prev.get(name, (0, 0))
            rx, tx = counts[name]
            down = getattr(p, "_down_since", None)
            ports.append(PortStatus(name=name, up=p.up, rx_bps=(rx - rx0) / dt,
                                    tx_bps=(tx - tx0) / dt, losses=p.losses,
                                    down_s=None if p.up or down is None else now - down))
        self._status_prev = (now, counts)
        vs = self.vehicle.summary()
        epochs = vs.get("epochs")
        faults, alarms = vs.get("faults"), vs.get("alarms")
        extra: dict[str, Any] = {}
        actions = vs.get("actions")
        if faults is None and isinstance(actions, dict):  # the ROV: its control actions
            extra = {k: actions[k] for k in sorted(actions) if actions[k]}
        extra.update(self.vehicle.status_fields())  # the vehicle's own fields
        return Snapshot(
            elapsed_s=now - self.t0,
            epochs=int(epochs) if isinstance(epochs, int) else self.records,
            faults=faults if isinstance(faults, int) else None,
            alarms=alarms if isinstance(alarms, int) else None,
            ports=tuple(ports),
            last_record_age_s=None if self._last_record_t is None
            else now - self._last_record_t,
            extra=extra, detail=tuple(self.vehicle.status_detail()),
            autopilot=None if self._echo is None else self._echo.view(now))

    def close(self) -> dict[str, Any]:
        """Finish the vehicle, close everything, write ``summary.json``; returns the summary."""
        if self._closed:
            return self._summary
        self._closed = True
        v = self.vehicle
        try:
            if self._started:
                v.finish()
        finally:
            for port in self.ports.values():
                port.close()
            if self._own_output and self.mavlink_output is not None:
                self.mavlink_output.close()
            if self._own_router and self.router is not None:
                self.router.close()
            self.epochs.close()
            if self.own_recorder and self.recorder is not None:
                self.recorder.close()
        self._summary = self.summary()
        self.epochs.write_summary(self._summary)
        return self._summary

    def summary(self) -> dict[str, Any]:
        s = dict(self.vehicle.summary())
        s["vehicle"] = self.vehicle.name
        if self.ports:
            s["port"] = next(iter(self.ports.values())).counters()
            s["ports"] = {name: p.counters() for name, p in self.ports.items()}
        if self._own_output and self.mavlink_output is not None:
            s["mavlink_out"] = self.mavlink_output.counters()
        if self.router is not None:
            s["router"] = self.router.summary()
        if self.recorder is not None:
            s["recorder"] = self.recorder.counters()
        epochs_file = self.epochs.counters()
        if epochs_file is not None:
            s["epochs_file"] = epochs_file
        if self.loop is not None:
            s.update(self.loop.stats.summary())
        s["runtime"] = {"stopped_by": self.stopped_by or "end",
                        "iterations": self.iterations,
                        "elapsed_s": round(self.clock() - self.t0, 3)}
        return s

    # ------------------------------------------------------------------ the loop

    def run(self, max_steps: int | None = None,
            until: Callable[[], bool] | None = None) -> dict[str, Any]:
        """Start, loop until a signal, ``duration_s``, ``max_steps`` or ``until()``, close;
        returns the summary."""
        previous: dict[signal.Signals, Any] = {}
        if self.handle_signals and threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGTERM, signal.SIGINT):
                previous[sig] = signal.signal(sig, self._on_signal)
        try:
            self.start()
            v = self.vehicle
            if v.pacing == "period":
                self.loop = FixedRateLoop(v.period_s, clock=self.clock, sleep=self.sleep)

                def paced(k: int, t: float) -> bool:
                    if self._should_stop(max_steps, until):
                        return False
                    self.step(t)
                    return not self._should_stop(max_steps, until)

                self.loop.run(paced)
            else:
                while not self._should_stop(max_steps, until):
                    self.step()
                    idle = v.idle_s()
                    if idle > 0:
                        self.sleep(min(idle, v.period_s))
        finally:
            try:
                summary = self.close()
            finally:
                for sig, handler in previous.items():
                    signal.signal(sig, handler)
        return summary
