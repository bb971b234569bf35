"""The rover's MAVLink side: its pipeline behind the router, one process for the passthrough
and the detector.

On a rover with an autopilot, ``fdi-bridge run --config X`` (or ``fdi-bridge mavlink``) with
``[rover]`` and ``[mavlink]`` tables runs the rover on the one runtime
(:class:`~firmware_host.runtime.runner.Runner`), which starts the router and has the rover
vehicle (:class:`~firmware_host.rover.vehicle.RoverVehicle`) call :func:`attach_rover`, which
wires a :class:`~firmware_host.rover.pipeline.RoverPipeline` to a
:class:`~firmware_host.mavlink.router.Router`:

* :class:`RouterRoverSink` (an ``EpochSink``) sends, through a
  :class:`~firmware_host.runtime.mavout.RouterOutput`, what
  :class:`~firmware_host.rover.outputs.MavlinkGpsSink` sends -- GPS_INPUT with the corrected fix
  (fix type, GPS week and ms, accuracies raised on replaced fixes), STATUSTEXT on alarm and
  recovery, the HOLD request -- through the router's non-blocking API, so the detector's thread
  never waits on a socket; the router's component sends the heartbeat. The detector statistics
  go to NAMED_VALUE_FLOAT (:data:`STAT_NAMES`) at the router's ``stats_hz``.
* :class:`LiveRoverIsolator` registers the numeric fields of
  :class:`~fdi.rover.RoverDetectorParams` in the router's
  :class:`~firmware_host.mavlink.params.ParamStore` (``FDI_ALPHA``, ``FDI_WINDOW``, ...). A
  PARAM_SET from a ground station marks them changed (router thread); the isolator takes the new
  values at its next epoch, in the detector's own thread, so an epoch never sees half a change.
"""

from __future__ import annotations

import logging
import threading

from fdi.rover import Decision, FixInput, RoverDetectorParams, RoverIsolator
from firmware_host.mavlink.params import ParamStore
from firmware_host.mavlink.router import Router
from firmware_host.rover.outputs import MavlinkGpsSink
from firmware_host.rover.pipeline import EpochOutcome, RoverPipeline
from firmware_host.runtime.config import RoverConfig
from firmware_host.runtime.mavout import RouterOutput, RouterPort

log = logging.getLogger("fdi_bridge.mavlink_rover")

PARAM_PREFIX = "FDI"

STAT_NAMES = {
    "GPS_CHI2R": "chi-square test ratio F(k) / T_d (eq. 1-6); > 1 is a fault",
    "GPS_GREYH": "grey residual ratio, horizontal: |ε(k)| / gate (eq. 18)",
    "GPS_GREYU": "grey residual ratio, vertical",
    "GPS_CONSEC": "fixes replaced in a row",
    "GPS_FAULT": "1 when this epoch's fix was judged faulty",
    "GPS_ALARM": "1 while the alarm (stop automatic navigation) is up",
}
"""NAMED_VALUE_FLOAT names (at most 10 characters) and what they carry."""


def _ratio(value: float | None, limit: float | None) -> float | None:
    if value is None or limit is None or limit <= 0.0:
        return None
    return value / limit


def decision_stats(d: Decision) -> dict[str, float]:
    """The NAMED_VALUE_FLOAT values of one epoch's decision (absent statistics left out)."""
    out = {
        "GPS_CHI2R": _ratio(d.chi2, d.chi2_threshold),
        "GPS_GREYH": _ratio(d.grey_res_h, d.grey_gate_h),
        "GPS_GREYU": _ratio(d.grey_res_u, d.grey_gate_u),
        "GPS_CONSEC": float(d.consecutive),
        "GPS_FAULT": float(d.fault),
        "GPS_ALARM": float(d.alarm),
    }
    return {k: v for k, v in out.items() if v is not None}


class RouterRoverSink:
    """EpochSink: the rover's MAVLink output through the router (see the module docstring)."""

    def __init__(self, cfg: RoverConfig, router: RouterPort) -> None:
        self.output = RouterOutput(router)
        self.gps = MavlinkGpsSink(cfg, endpoint=self.output)

    @property
    def sent(self) -> int:
        """GPS_INPUT messages handed to the router."""
        return self.gps.sent

    def emit(self, out: EpochOutcome) -> None:
        self.gps.emit(out)
        for name, value in decision_stats(out.decision).items():
            self.output.send_named_value(name, value)

    def close(self) -> None:
        self.gps.close()


class LiveRoverIsolator(RoverIsolator):
    """A :class:`RoverIsolator` whose parameters follow a :class:`ParamStore` (module docstring)."""

    def __init__(self, params: RoverDetectorParams, store: ParamStore, prefix: str = PARAM_PREFIX):
        self.store = store
        self.base = params
        self.names = store.register_dataclass(prefix, params)
        self._changed = threading.Event()
        self.changes_applied = 0
        super().__init__(store.dataclass_view(params, self.names))  # override file values
        mine = set(self.names.values())
        store.on_change(lambda name, _value: self._changed.set() if name in mine else None)

    def step(self, fix: FixInput) -> Decision:
        if self._changed.is_set():
            self._changed.clear()
            self.update_params(self.store.dataclass_view(self.base, self.names))
            self.changes_applied += 1
            log.info("detector parameters changed: %s", self.p)
        return super().step(fix)


def attach_rover(
    pipeline: RoverPipeline, router: RouterPort, prefix: str = PARAM_PREFIX
) -> RouterRoverSink:
    """Make ``pipeline`` (before its first epoch) use ``router``: live parameters (the
    :class:`~firmware_host.mavlink.router.Router`'s parameter store), outputs."""
    if not isinstance(router, Router):
        raise TypeError(f"live parameters need the MAVLink router, not {type(router).__name__}")
    if pipeline.epochs:
        raise ValueError("attach_rover needs a pipeline that has not processed an epoch yet")
    pipeline.isolator = LiveRoverIsolator(pipeline.cfg.detector, router.params, prefix)
    sink = RouterRoverSink(pipeline.cfg, router)
    pipeline.sinks.append(sink)
    return sink
