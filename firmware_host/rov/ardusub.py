"""The ROV behind the MAVLink router: heading hold through an autopilot, FDI to the operator.

Where the vehicle is driven through an autopilot (ArduSub) instead of the Outland link, the
heading-hold loop (:class:`~firmware_host.rov.control.RovController`: compass FDI, substitution,
PID) reads the vehicle's heading from the autopilot (via
:meth:`Router.listen <firmware_host.mavlink.router.Router.listen>`): ATTITUDE's ``yaw`` (the
EKF's), or with ``heading = "raw_compass"`` the compass of RAW_IMU / SCALED_IMU* levelled with
ATTITUDE's roll and pitch (:mod:`drivers.mavlink.compass`, ArduPilot's convention), with the
autopilot's gyro as the FDI's witness where ``gyro`` says so. It sends its thrust as
MANUAL_CONTROL (or, ``output = "rc_override"``, RC_CHANNELS_OVERRIDE on the RCMAP channels:
:func:`rc_override_channels`) with the ground station's system id (``pilot_system_id``), the
bridge's own component id and the vehicle as target: ArduSub takes pilot input only from its
ground station's system id (``MAV_GCS_SYSID``, ``SYSID_MYGCS`` before 4.7; any component).

The router's thread only queues the frames (:class:`Inbox`); each period's step decodes the
ones that arrived, in order, so a recording of what each step took (the ``ardusub rx``
channel) replays to the same records (:mod:`firmware_host.rov.replay`). Frames or values that
cannot be used are counted by reason (``inputs_rejected``) and logged, rate-limited.

:class:`ArduSubRovVehicle` is this loop as a vehicle of the runtime
(:class:`~firmware_host.runtime.runner.Runner`, period-paced, no port of its own: the router's
autopilot link is its input and output).

:class:`RovOperatorSink` is the per-epoch sink of an ROV vehicle (this module's, or
:class:`~firmware_host.rov.vehicle.OutlandRovVehicle` on the Outland link when a ``[mavlink]``
router is attached), writing to a :class:`~firmware_host.runtime.mavout.MavlinkOutput`: per
epoch the corrected heading and the detector's statistics
as NAMED_VALUE_FLOAT (:data:`STAT_NAMES`, sent at the router's ``stats_hz``), and STATUSTEXT for
each detector event and for a telemetry dropout, with severities.

ArduSub's rules (docs/rov-ardusub.md; ``[rov.ardusub]``,
:class:`~firmware_host.runtime.config_rov.ArduSubConfig`):

* ArduSub takes MANUAL_CONTROL only from its ground station's system id (``MAV_GCS_SYSID``:
  ``GCS_MAVLINK_Sub::handle_message``, ``GCS::sysid_is_gcs``; the component is not checked):
  the router sends it from ``[mavlink] pilot_system_id`` and the bridge's ``component_id``;
* ``steer = false``: detect only (the detector runs on the pilot's yaw, nothing is sent);
* the bridge steers (:data:`STEERING`) only while the autopilot's HEARTBEAT is fresh
  (``heartbeat_timeout_s``), says it is armed, and its mode is one of ``modes`` (modes whose
  pilot yaw is MANUAL_CONTROL ``r``: MANUAL, STABILIZE, ACRO, ALT_HOLD, POSHOLD; in AUTO, GUIDED,
  CIRCLE, SURFACE the autopilot owns the heading). Otherwise it sends nothing of its own and the
  pilot's MANUAL_CONTROL passes unchanged; each change of state is logged and sent as a
  STATUSTEXT once;
* the pilot's MANUAL_CONTROL from a ground station is intercepted by the router
  (:meth:`Router.intercept <firmware_host.mavlink.router.Router.intercept>`): while the bridge
  steers, its ``x``, ``y``, ``z``, buttons and extension fields (``buttons2``, ``s``, ``t``,
  ``aux1-6``) go out unchanged with the bridge's ``r``, at the bridge's 5 Hz, and a frame that
  changes the buttons is sent on at once (every button edge reaches ArduSub, in order:
  :class:`PilotInput`); a pilot ``|r|`` above ``yaw_dead_band`` takes over at once (that
  frame sent on with the pilot's ``r``, then the pilot's frames pass unchanged, "pilot" in the
  records, logged), and after the stick has been back within the dead band for
  ``pilot_release_s`` the bridge holds the heading the pilot left it on;
* never mask ArduSub's pilot-input failsafe (``FS_PILOT_INPUT``, after ``FS_PILOT_TIMEOUT``,
  3 s by default): once a pilot has been seen, the bridge stops sending when the pilot's
  MANUAL_CONTROL has been silent for ``pilot_timeout_s`` (< 3 s);
* ArduSub counts the bridge's MANUAL_CONTROL as its GCS's heartbeat (``sysid_mygcs_seen``):
  with ``send_without_pilot = false`` (the default) the bridge sends only while the pilot's
  MANUAL_CONTROL or the GCS's HEARTBEAT came within ``pilot_timeout_s`` ("no_pilot"
  otherwise), so the GCS failsafe (``FS_GCS_ENABLE``) is not masked; ``true`` is the
  unattended hold, whose frames hide it while the bridge runs and steers;
* heading silence (no ATTITUDE): the controller's dropout rule holds the last command for
  ``dropout_hold_s``, then neutral yaw (``r = 0``, the pilot's other axes still passed), with a
  STATUSTEXT; ATTITUDE back: resumes, said (:class:`RovOperatorSink`).

MANUAL_CONTROL from a :class:`~drivers.outland.link.ThrusterCommand` (ArduSub's pilot axes):
``x = 10 (port + starboard) / 2`` (forward), ``r = 10 (port - starboard) / 2`` (yaw, positive
clockwise), ``y = 10 lateral``, ``z = 500 + 5 vertical`` (0..1000, 500 neutral), all in
-1000..1000 and clamped.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import threading
from collections import Counter
from collections.abc import Callable
from typing import Any

from drivers.mavlink import io as mio
from drivers.mavlink.compass import heading_rate_dps, mag_from_message, tilt_compensated_heading_deg
from drivers.mavlink.framer import MavFrame
from drivers.mavlink.modes import MODES
from drivers.outland.link import ThrusterCommand
from drivers.ratelog import RateLimitedLog
from fdi.errors import ConfigError, DecodeError
from fdi.heading_ft import HeadingDecision
from fdi.lms_fir import wrap180
from firmware_host.rov.base import RovVehicleBase
from firmware_host.rov.config import RovConfig
from firmware_host.rov.control import RovController, epoch_record
from firmware_host.runtime.config_rov import ArduSubConfig
from firmware_host.runtime.mavout import MavlinkOutput, RouterOutput, RouterPort
from firmware_host.runtime.records import EpochLog
from firmware_host.runtime.vehicle import Context, MavlinkSpec, PortSpec, Tap

log = logging.getLogger(__name__)

STEERING = "steer"
"""The bridge's state while it commands the yaw (others: :data:`STATE_TEXT`)."""

HANDBACK = "handback"
"""While the heading is substituted, the substitute is not trusted (:meth:`RovAutopilotLoop.
_supervise`): the bridge stops steering and the pilot's yaw (neutral without one) goes on."""

STATE_TEXT: dict[str, tuple[int, str]] = {
    STEERING: (mio.MAV_SEVERITY_NOTICE, "FDI heading hold: steering yaw"),
    "no_heartbeat": (mio.MAV_SEVERITY_WARNING, "FDI heading hold: no autopilot heartbeat"),
    "disarmed": (mio.MAV_SEVERITY_INFO, "FDI heading hold: vehicle disarmed, not steering"),
    "mode": (mio.MAV_SEVERITY_WARNING, "FDI heading hold: mode {mode} not steered"),
    "pilot": (mio.MAV_SEVERITY_NOTICE, "FDI heading hold: pilot yaw, yielding"),
    "pilot_silent": (mio.MAV_SEVERITY_WARNING, "FDI heading hold: pilot input lost, not sending"),
    "no_pilot": (mio.MAV_SEVERITY_WARNING,
                 "FDI heading hold: no pilot or ground station, not sending"),
    "detect_only": (mio.MAV_SEVERITY_INFO, "FDI heading hold: detect only, not steering"),
    HANDBACK: (mio.MAV_SEVERITY_CRITICAL, "FDI heading: substitute untrusted, yaw to pilot"),
}
_SUB_MODE_NAMES = {n: name for name, n in MODES["sub"].items()}

STAT_NAMES = {
    "HDG": "heading used by the hold (corrected), deg",
    "HDG_MEAS": "compass heading as measured, deg",
    "HDG_E2": "LMS prediction error e², deg²",
    "HDG_R": "R(k), the detector's signal-to-noise criterion",
    "HDG_V": "V(k), the detector's second criterion",
    "HDG_FAULT": "1 while a confirmed compass fault is handled",
    "HDG_SUBST": "1 while the heading is substituted (not the sensor's)",
}
"""NAMED_VALUE_FLOAT names (at most 10 characters) and what they carry."""

# Detector events -> (MAV_SEVERITY, text).
EVENT_TEXT: dict[str, tuple[int, str]] = {
    "suspect": (mio.MAV_SEVERITY_WARNING, "FDI compass: suspect"),
    "confirmed": (mio.MAV_SEVERITY_CRITICAL, "FDI compass: fault confirmed, heading substituted"),
    "stuck": (mio.MAV_SEVERITY_CRITICAL, "FDI compass: sensor stuck, heading substituted"),
    "dismissed": (mio.MAV_SEVERITY_INFO, "FDI compass: suspicion dismissed"),
    "compensating": (mio.MAV_SEVERITY_WARNING, "FDI compass: compensating the fault"),
    "fallback": (mio.MAV_SEVERITY_ALERT, "FDI compass: fallback, check the heading"),
    "recovered": (mio.MAV_SEVERITY_NOTICE, "FDI compass: sensor recovered"),
}
ACTION_TEXT: dict[str, tuple[int, str]] = {
    "hold": (mio.MAV_SEVERITY_WARNING, "FDI compass: telemetry lost, holding last command"),
    "neutral": (mio.MAV_SEVERITY_CRITICAL, "FDI compass: telemetry lost, neutral thrust"),
}


def _axis(value: float, lo: int = -1000, hi: int = 1000) -> int:
    return min(max(round(value), lo), hi)


def manual_control_axes(cmd: ThrusterCommand) -> tuple[int, int, int, int]:
    """``(x, y, z, r)`` of MANUAL_CONTROL for ``cmd`` (see the module docstring)."""
    return (
        _axis(10.0 * (cmd.port_pct + cmd.starboard_pct) / 2.0),
        _axis(10.0 * cmd.lateral_pct),
        _axis(500.0 + 5.0 * cmd.vertical_pct, 0, 1000),
        _axis(10.0 * (cmd.port_pct - cmd.starboard_pct) / 2.0),
    )


class RovOperatorSink:
    """``on_epoch`` sink: heading, statistics and events to the operator (module docstring)."""

    def __init__(self, output: MavlinkOutput) -> None:
        self.output = output
        self._action = "init"

    def __call__(self, rec: dict[str, Any]) -> None:
        out = self.output
        values = {
            "HDG": rec.get("heading_used"),
            "HDG_MEAS": rec.get("heading_meas"),
            "HDG_E2": rec.get("e2"),
            "HDG_R": rec.get("snr"),
            "HDG_V": rec.get("V"),
            "HDG_FAULT": float(bool(rec.get("fault"))),
            "HDG_SUBST": float(rec.get("source", "sensor") != "sensor"),
        }
        for name, value in values.items():
            if value is not None and math.isfinite(float(value)):
                out.send_named_value(name, float(value))
        event = str(rec.get("event") or "")
        if event in EVENT_TEXT:
            severity, text = EVENT_TEXT[event]
            kind = rec.get("fault_kind") or ""
            out.send_statustext(severity, f"{text} ({kind})" if kind else text)
        action = str(rec.get("action", ""))
        if self._action == "init" and action == "hold":
            return  # the first periods before the first telemetry: nothing was lost yet
        if action != self._action and action in ACTION_TEXT:
            out.send_statustext(*ACTION_TEXT[action])
        elif self._action in ACTION_TEXT and action not in ACTION_TEXT:
            out.send_statustext(mio.MAV_SEVERITY_NOTICE, "FDI compass: telemetry back")
        self._action = action


class Inbox:
    """The autopilot's and the pilot's frames as they arrive (router thread), taken once per
    period by the loop, which decodes them in arrival order (so a recording of what each step
    took replays exactly: :mod:`firmware_host.rov.replay`)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._frames: list[bytes] = []

    def push(self, raw: bytes) -> None:
        with self._lock:
            self._frames.append(raw)

    def take(self) -> list[bytes]:
        with self._lock:
            frames, self._frames = self._frames, []
        return frames


class AutopilotListener:
    """One message of the autopilot (``(system, component)`` = ``autopilot``) into the inbox,
    counted in ``received``."""

    def __init__(self, router: RouterPort, message: str, inbox: Inbox,
                 autopilot: tuple[int, int] = (1, 1)) -> None:
        self.autopilot = autopilot
        self.inbox = inbox
        self.received = 0
        router.listen(message, self._on_frame)

    def _on_frame(self, frame: MavFrame) -> None:
        if (frame.sysid, frame.compid) != self.autopilot:
            return
        self.received += 1
        self.inbox.push(frame.raw)


_HEARTBEAT_ID = mio.message_id("HEARTBEAT")
_MANUAL_CONTROL_ID = mio.message_id("MANUAL_CONTROL")
_NO_EXT = mio.ManualControlExt()


def _source_and_id(raw: bytes) -> tuple[int, int, int] | None:
    """``(system, component, message id)`` from a framed packet's header (MAVLink 2 or 1)."""
    if len(raw) >= 10 and raw[0] == 0xFD:
        return raw[5], raw[6], raw[7] | (raw[8] << 8) | (raw[9] << 16)
    if len(raw) >= 6 and raw[0] == 0xFE:
        return raw[3], raw[4], raw[5]
    return None


class PilotInput:
    """The pilot's MANUAL_CONTROL and the ground station's HEARTBEAT, intercepted in the router.

    Not steering: the pilot's frames pass unchanged. While the bridge steers, they are held
    back (each period the bridge sends the pilot's axes with its own yaw), except, sent on at
    once as the bridge's frame (:meth:`_resend`, in the router's thread, the pilot's fields):

    * a frame whose ``buttons``/``buttons2`` differ from the buttons the vehicle last got,
      with the bridge's current yaw: every button edge reaches ArduSub, in order and when the
      pilot made it (ArduSub acts on edges: arm, disarm, mode, lights, gain); a tap shorter
      than a period is a press and a release, both sent;
    * a frame whose ``|r|`` is above the dead band, with the pilot's yaw (a takeover).

    Every frame the bridge sends to the vehicle, here or each period
    (:meth:`RovAutopilotLoop._send_command`), is composed and queued under :attr:`lock` and
    carries the buttons the vehicle last got (:attr:`wire`): a period's frame never undoes an
    edge sent a moment before it. Frames for this vehicle, and the HEARTBEATs of the ground
    station (system ``gcs_system_id``: the pilot's presence), go to the inbox.
    """

    def __init__(self, router: RouterPort, vehicle: int, dead_band: int, inbox: Inbox,
                 output: MavlinkOutput, gcs_system_id: int) -> None:
        self.vehicle = vehicle
        self.dead_band = dead_band
        self.inbox = inbox
        self.output = output
        self.gcs_system_id = gcs_system_id
        self.lock = threading.Lock()
        self.steering = False  # set by the loop under the lock
        self.r = 0  # the bridge's current yaw, sent with an edge
        self.wire = (0, 0)  # (buttons, buttons2) the vehicle last got, from the pilot or us
        self.received = 0
        self.gcs_heartbeats = 0
        self.edges_sent = 0
        self.takeovers_sent = 0
        router.intercept("MANUAL_CONTROL", self._on_manual_control)
        router.intercept("HEARTBEAT", self._on_heartbeat)

    def _on_heartbeat(self, frame: MavFrame) -> bool:
        if frame.sysid == self.gcs_system_id and frame.sysid != self.vehicle:
            self.gcs_heartbeats += 1
            self.inbox.push(frame.raw)
        return True  # forwarded as it is

    def _on_manual_control(self, frame: MavFrame) -> bool:
        msg = mio.decode_packet(frame.raw)
        if msg is None or int(msg.target) != self.vehicle:
            return True  # not for this vehicle (ArduSub ignores it too): forwarded as it is
        self.received += 1
        self.inbox.push(frame.raw)
        ext = mio.ManualControlExt.of(msg)
        buttons = (int(msg.buttons), ext.buttons2)
        with self.lock:
            if not self.steering:
                self.wire = buttons
                return True
            if abs(int(msg.r)) > self.dead_band:
                self.takeovers_sent += 1
                self._resend(msg, int(msg.r), ext)
            elif buttons != self.wire:
                self.edges_sent += 1
                self._resend(msg, self.r, ext)
            return False

    def _resend(self, msg: Any, r: int, ext: mio.ManualControlExt) -> None:
        """The pilot's frame ``msg`` as the bridge's, with yaw ``r`` (under the lock)."""
        self.output.send_manual_control(self.vehicle, int(msg.x), int(msg.y), int(msg.z), r,
                                        int(msg.buttons), ext)
        self.wire = (int(msg.buttons), ext.buttons2)


UINT16_MAX = 0xFFFF
RC_RELEASE = 0


def _pwm(value: float, lo: int = 1100, hi: int = 1900) -> int:
    return min(max(round(value), lo), hi)


def rc_override_channels(acfg: ArduSubConfig, axes: tuple[int, int, int, int] | None
                         ) -> tuple[int, ...]:
    """RC_CHANNELS_OVERRIDE's 18 values for MANUAL_CONTROL axes ``(x, y, z, r)``, or the
    release of the bridge's channels when ``axes`` is None.

    ArduSub's joystick mapping at gain 1 (``transform_manual_control_to_rc_override``:
    ``1500 + 0.4 r`` for yaw, forward and lateral, ``1100 + 0.8 z`` for throttle; 1100..1900),
    on the ``RCMAP_*`` channels of ``[rov.ardusub]``; the other channels 1-8 are UINT16_MAX
    (ignored), 9-18 are 0 (ignored), per the MAVLink spec. A release sets the bridge's four
    channels to 0 (back to the RC radio)."""
    ch = [UINT16_MAX] * 8 + [0] * 10
    slots = (acfg.rc_forward_channel, acfg.rc_lateral_channel, acfg.rc_throttle_channel,
             acfg.rc_yaw_channel)
    if axes is None:
        for c in slots:
            ch[c - 1] = RC_RELEASE
        return tuple(ch)
    x, y, z, r = axes
    for c, v in zip(slots, (_pwm(1500 + 0.4 * x), _pwm(1500 + 0.4 * y),
                            _pwm(1100 + 0.8 * z), _pwm(1500 + 0.4 * r)), strict=True):
        ch[c - 1] = v
    return tuple(ch)


COMPASS_RATE_PERIODS = 50
COMPASS_RATE_MIN = 0.9
"""The compass (or its gyro) must arrive in 90 % of the 50 periods from the first one."""

_RELEASE_ON = frozenset({"mode", "disarmed", "no_heartbeat", "detect_only", HANDBACK})


def _stamp_s(msg: Any) -> float | None:
    """A message's time stamp (s since the autopilot's boot), None without one."""
    for name, scale in (("time_boot_ms", 1e-3), ("time_usec", 1e-6)):
        v = getattr(msg, name, None)
        if isinstance(v, int) and v > 0:
            return v * scale
    return None


class StampedRate:
    """The heading's change over a period from its stamped rate samples, by the trapezoid rule.

    ATTITUDE's ``yawspeed`` (and RAW_IMU's gyro) is the rate *at* its time stamp, two samples
    a 200 ms period at 10 Hz, and the compass the witness compares with the integrated rate is
    the period's newest sample. The mean of a period's samples times the period (before) is a
    right-hand Riemann sum: the heading it gives at that stamp leads the vehicle's by half a
    sample times the rate then (0.5 deg in one of ArduSub's ~9.5 deg/s MANUAL kicks, 3.9 deg
    in a 77 deg/s turn), so every kick moved the innovation by that much and back. Here the
    area between consecutive samples is the trapezoid over their stamps, from the previous
    period's last sample to this period's last, and the period's rate is that area over the
    period: the integral is the heading at the newest stamp. A gap over ``max_gap_s`` (a lost
    stream, a reboot's stamps going back) or a sample without a stamp starts again: that
    period's rate is the mean of its samples.
    """

    def __init__(self, max_gap_s: float = 0.5) -> None:
        self.max_gap_s = max_gap_s
        self._last: tuple[float, float] | None = None  # (stamp s, rate deg/s)
        self._area = 0.0
        self._samples: list[float] = []
        self._joined = True

    def add(self, stamp_s: float | None, rate_dps: float) -> None:
        """One sample; ``stamp_s`` None (no stamp): the period falls back to the mean."""
        self._samples.append(rate_dps)
        last, self._last = self._last, (None if stamp_s is None else (stamp_s, rate_dps))
        if stamp_s is None or last is None or not 0.0 < stamp_s - last[0] <= self.max_gap_s:
            self._joined = False
            return
        self._area += 0.5 * (last[1] + rate_dps) * (stamp_s - last[0])

    def take(self, dt: float) -> float | None:
        """This period's rate (deg/s; None without samples); starts the next period."""
        samples, joined, area = self._samples, self._joined, self._area
        self._samples, self._joined, self._area = [], True, 0.0
        if not samples:
            self._last = None  # a silent period: the next one starts afresh
            return None
        return area / dt if joined else sum(samples) / len(samples)


class RovAutopilotLoop:
    """The ROV heading hold driven through an autopilot (see the module docstring).

    ``router`` None: no router (a replay): the loop reads ``inbox`` (loaded by the caller)
    and sends nothing; ``output`` gets the operator's telemetry (a null output in a replay).
    ``tx`` receives one line per command the loop sends (JSON: ``{"mc": [x, y, z, r,
    buttons]}`` or ``{"rc": [18 values]}``): the recorder's ``ardusub tx`` channel.
    """

    def __init__(
        self,
        cfg: RovConfig,
        router: RouterPort | None,
        *,
        ft: bool = True,
        vehicle_system_id: int = 1,
        on_epoch: Callable[[dict[str, Any]], None] | None = None,
        inbox: Inbox | None = None,
        output: MavlinkOutput | None = None,
    ) -> None:
        self.cfg = cfg
        self.acfg = cfg.ardusub
        self.router = router
        self.vehicle = vehicle_system_id
        self.ctl = RovController(cfg, ft=ft)
        self.inbox = inbox if inbox is not None else Inbox()
        a = self.acfg
        self.heading: AutopilotListener | None = None
        self.autopilot: AutopilotListener | None = None
        self.ahrs2: AutopilotListener | None = None
        self.compass: AutopilotListener | None = None
        self.pilot: PilotInput | None = None
        self._uses_compass = a.heading == "raw_compass" or a.gyro == "imu"
        if router is not None:
            ap = (vehicle_system_id, 1)
            self.heading = AutopilotListener(router, "ATTITUDE", self.inbox, ap)
            self.autopilot = AutopilotListener(router, "HEARTBEAT", self.inbox, ap)
            # AHRS2 (ArduPilot's second attitude estimate): a cross-check of a substitute
            self.ahrs2 = AutopilotListener(router, "AHRS2", self.inbox, ap)
            if self._uses_compass:
                self.compass = AutopilotListener(router, a.compass_message, self.inbox, ap)
        if output is None:
            assert router is not None, "a replay gives its own output"
            output = RouterOutput(router)
        self.output = output
        if router is not None:
            self.pilot = PilotInput(router, vehicle_system_id, a.yaw_dead_band, self.inbox,
                                    output, router.cfg.pilot_system_id)
        self.operator = RovOperatorSink(self.output)
        self.on_epoch = on_epoch
        self.t = 0.0
        self.armed = False
        self.mode: int | None = None
        self._hb_age: float | None = None  # s since the last HEARTBEAT; None: none yet
        self._pilot_axes: tuple[int, int, int, int, int] | None = None
        self._pilot_age = 0.0
        self._pilot_ext = _NO_EXT  # the newest pilot frame's extension fields
        self._gcs_age: float | None = None  # s since the ground station's HEARTBEAT; None: none
        self._pilot_has = False  # the pilot is steering (yaw above the dead band)
        self._centred_s = 0.0
        self._attitude: tuple[float, float] | None = None  # the newest (roll, pitch), rad
        self._rate = StampedRate()  # the gyro's samples, integrated over each period
        self.state = "init"
        self.states: Counter[str] = Counter()
        self.takeovers = 0
        self.sent = 0
        self.rc_releases = 0
        self.tx: list[bytes] = []  # this step's commands (see the class docstring)
        self.taken: Counter[str] = Counter()  # frames processed, by message
        self.rejected: Counter[str] = Counter()  # frames or values not used, by reason
        self._ratelog = RateLimitedLog(log)
        self._compass_periods = 0
        # The substitute's supervision (:meth:`_supervise`): this period's other headings,
        # how long the substitute has been dead reckoning, and the hand-backs so far.
        self._ahrs2_yaw: float | None = None
        self._compass_yaw: float | None = None
        self._dr_s = 0.0
        self.handbacks = 0
        self.handback_reason = ""
        self._pulled = False  # this fault's other headings left the judged one (see above)
        self._compass_hits = 0
        self.compass_slow_hz: float | None = None  # said once: the compass is too slow

    # -- inputs -------------------------------------------------------------------------

    def _reject(self, why: str) -> None:
        self.rejected[why] += 1
        self._ratelog.warning(f"ardusub input not used: {why}",
                              f"{self.rejected[why]} so far")

    def _absorb(self, frames: list[bytes]) -> tuple[
            float | None, float | None, float | None,
            tuple[bool, int] | None, tuple[int, int, int, int, int] | None]:
        """This period's frames, in arrival order: ``(heading, attitude yaw, yaw rate,
        heartbeat, pilot axes)``, each the newest (the rate: :class:`StampedRate`'s)."""
        a = self.acfg
        yaw_att: float | None = None
        compass: float | None = None
        hb: tuple[bool, int] | None = None
        pilot: tuple[int, int, int, int, int] | None = None
        for raw in frames:
            msg = mio.decode_packet(raw)
            if msg is None:
                self._reject("undecodable")
                continue
            kind = msg.get_type()
            self.taken[kind] += 1
            try:
                if kind == "ATTITUDE":
                    roll, pitch, yaw = float(msg.roll), float(msg.pitch), float(msg.yaw)
                    if not all(math.isfinite(v) for v in (roll, pitch, yaw)):
                        self._reject("attitude_not_finite")
                        continue
                    self._attitude = (roll, pitch)
                    yaw_att = math.degrees(yaw) % 360.0
                    if a.gyro == "attitude":
                        rate = heading_rate_dps((float(msg.rollspeed), float(msg.pitchspeed),
                                                 float(msg.yawspeed)), roll, pitch)
                        if rate is None:
                            self._reject("rate_not_finite")
                        else:
                            self._rate.add(_stamp_s(msg), rate)
                elif kind == "AHRS2":
                    yaw2 = float(msg.yaw)
                    if math.isfinite(yaw2):
                        self._ahrs2_yaw = math.degrees(yaw2) % 360.0
                elif kind == "HEARTBEAT":
                    hb = (bool(int(msg.base_mode) & mio.MAV_MODE_FLAG_SAFETY_ARMED),
                          int(msg.custom_mode))
                elif kind == "MANUAL_CONTROL":
                    pilot = (int(msg.x), int(msg.y), int(msg.z), int(msg.r), int(msg.buttons))
                if kind == a.compass_message and self._uses_compass:
                    sample = mag_from_message(msg)
                    if sample is None:
                        self._reject("compass_empty")
                        continue
                    if self._attitude is None:
                        self._reject("compass_before_attitude")  # no roll/pitch to level it
                        continue
                    roll, pitch = self._attitude
                    if a.heading == "raw_compass":
                        h = tilt_compensated_heading_deg(sample.field_mgauss, roll, pitch,
                                                         a.declination_deg)
                        if h is None:
                            self._reject("compass_field_too_weak")
                        else:
                            compass = (h + a.compass_offset_deg) % 360.0
                    elif self._attitude is not None:  # heading from ATTITUDE: a cross-check
                        h = tilt_compensated_heading_deg(sample.field_mgauss, roll, pitch,
                                                         a.declination_deg)
                        if h is not None:
                            self._compass_yaw = (h + a.compass_offset_deg) % 360.0
                    if a.gyro == "imu":
                        rate = (None if sample.gyro_rad_s is None
                                else heading_rate_dps(sample.gyro_rad_s, roll, pitch))
                        if rate is None:
                            self._reject("gyro_missing")
                        else:
                            self._rate.add(_stamp_s(msg), rate)
            except DecodeError:
                self._reject(f"{kind.lower()}_fields")
        heading = compass if a.heading == "raw_compass" else yaw_att
        rate = self._rate.take(self.cfg.period_s)
        if self._uses_compass:
            self._check_compass_rate(compass is not None or rate is not None)
        return heading, yaw_att, rate, hb, pilot

    def _check_compass_rate(self, got: bool) -> None:
        """Said once: the compass message comes slower than the hold's period (fewer than
        :data:`COMPASS_RATE_MIN` of :data:`COMPASS_RATE_PERIODS` periods had one)."""
        if not got and self._compass_hits == 0:
            return  # counted from the first compass message on
        self._compass_periods += 1
        self._compass_hits += got
        if self._compass_periods == COMPASS_RATE_PERIODS:
            share = self._compass_hits / COMPASS_RATE_PERIODS
            if share < COMPASS_RATE_MIN:
                hz = share / self.cfg.period_s
                text = (f"FDI compass: {self.acfg.compass_message} at {hz:.1f} Hz, below "
                        f"the hold's {1 / self.cfg.period_s:.0f} Hz (MAVn_RAW_SENS)")
                log.warning("%s", text)
                self.output.send_statustext(mio.MAV_SEVERITY_WARNING, text)
                self.compass_slow_hz = round(hz, 2)

    # -- the gate -----------------------------------------------------------------------

    def _gate(self) -> str:
        """Why the bridge may not steer now, or :data:`STEERING`."""
        a = self.acfg
        if not a.steer:
            return "detect_only"
        if self._hb_age is None or self._hb_age > a.heartbeat_timeout_s + 1e-9:
            return "no_heartbeat"
        if not self.armed:
            return "disarmed"
        name = _SUB_MODE_NAMES.get(self.mode if self.mode is not None else -1)
        if name not in a.modes:
            return "mode"
        if self._pilot_axes is not None and self._pilot_age > a.pilot_timeout_s + 1e-9:
            return "pilot_silent"
        if not a.send_without_pilot and not self._pilot_present():
            return "no_pilot"
        return STEERING

    def _pilot_fresh(self) -> bool:
        """The pilot's MANUAL_CONTROL came within ``pilot_timeout_s``."""
        return (self._pilot_axes is not None
                and self._pilot_age <= self.acfg.pilot_timeout_s + 1e-9)

    def _pilot_present(self) -> bool:
        """A pilot or ground station is there: its MANUAL_CONTROL or the GCS's HEARTBEAT came
        within ``pilot_timeout_s``."""
        return self._pilot_fresh() or (
            self._gcs_age is not None and self._gcs_age <= self.acfg.pilot_timeout_s + 1e-9)

    def _scan_pilot(self, frames: list[bytes]) -> list[bytes]:
        """The ground station's HEARTBEATs taken out of the period's frames (their age is the
        pilot's presence: :meth:`_pilot_present`), and the extension fields of the newest pilot
        MANUAL_CONTROL kept (passed on unchanged); the other frames, in order."""
        rest: list[bytes] = []
        gcs = False
        for raw in frames:
            head = _source_and_id(raw)
            if head is not None and head[2] == _HEARTBEAT_ID and head[:2] != (self.vehicle, 1):
                gcs = True
                self.taken["GCS_HEARTBEAT"] += 1
                continue
            if head is not None and head[2] == _MANUAL_CONTROL_ID:
                msg = mio.decode_packet(raw)
                if msg is not None:
                    self._pilot_ext = mio.ManualControlExt.of(msg)
            rest.append(raw)
        if gcs:
            self._gcs_age = 0.0
        elif self._gcs_age is not None:
            self._gcs_age += self.cfg.period_s
        return rest

    def _pilot_yaw(self, dt: float) -> bool:
        """True while the pilot steers the yaw (takeover, then ``pilot_release_s`` centred)."""
        r = self._pilot_axes[3] if self._pilot_axes is not None else 0
        if abs(r) > self.acfg.yaw_dead_band:
            if not self._pilot_has and self.acfg.steer:
                self.takeovers += 1
                log.warning("pilot yaw %d above the dead band %d: the pilot steers", r,
                            self.acfg.yaw_dead_band)
            self._pilot_has = True
            self._centred_s = 0.0
        elif self._pilot_has:
            self._centred_s += dt
            if self._centred_s >= self.acfg.pilot_release_s - 1e-9:
                self._pilot_has = False
        return self._pilot_has

    def _others(self, yaw_att: float | None) -> list[tuple[str, float]]:
        """This period's headings other than the one the FDI judges: the EKF's (when the
        FDI judges the raw compass), AHRS2's, the raw compass (when it judges the EKF's)."""
        out: list[tuple[str, float]] = []
        if self.acfg.heading == "raw_compass" and yaw_att is not None:
            out.append(("EKF yaw", yaw_att))
        if self._ahrs2_yaw is not None:
            out.append(("AHRS2", self._ahrs2_yaw))
        if self.acfg.heading == "attitude" and self._compass_yaw is not None:
            out.append(("compass", self._compass_yaw))
        self._ahrs2_yaw = self._compass_yaw = None
        return out

    def _supervise(self, dec: HeadingDecision, meas: float | None, yaw_att: float | None,
                   dt: float) -> bool:
        """A substitute may never steer the vehicle further off than no fault tolerance
        would: while the heading is substituted, it is not trusted (True: hand the yaw back to
        the pilot, latched until the compass is taken back) when every other heading the link
        carries and the judged one (not when it is stuck) agree with each other within
        ``handback_deg`` and are all more than that from it (at least one besides the judged
        heading), or when it has been gyro dead reckoning for ``substitute_max_s`` (its error grows
        with the gyro's bias and scale errors, and no compass anchors it)."""
        a = self.acfg
        others = self._others(yaw_att)
        if not dec.fault or dec.heading_used is None:
            if self.handback_reason:
                log.warning("FDI heading: compass taken back, steering resumes")
                self.output.send_statustext(mio.MAV_SEVERITY_NOTICE,
                                            "FDI heading: compass back, steering resumes")
            self._dr_s = 0.0
            self.handback_reason = ""
            self._pulled = False
            return False
        if self.handback_reason:
            return True
        if meas is not None and dec.kind != "stuck":
            # The judged compass votes too, unless it is stuck. A magnetometer fault pulls the
            # EKF's yaw and AHRS2 towards itself, slowly: once they have disagreed with the
            # judged compass by half the gate during this fault, their agreement later says
            # nothing (they may have followed it), and only the time bound is left.
            if any(abs(wrap180(h - meas)) > 0.5 * a.handback_deg for _, h in others):
                self._pulled = True
            others = [] if self._pulled else [*others, (
                "compass" if self.acfg.heading == "raw_compass" else "EKF yaw", meas)]
        w = self.ctl.heading.witness
        compensated = dec.source == "gyro" and w.fault and w.offset is not None
        self._dr_s = 0.0 if compensated else self._dr_s + dt
        reason = ""
        if a.substitute_max_s > 0.0 and self._dr_s > a.substitute_max_s + 1e-9:
            reason = f"dead reckoning for {self._dr_s:.0f} s"
        elif a.handback_deg > 0.0 and others and (len(others) > 1 or dec.kind == "stuck"):
            used = dec.heading_used
            offs = [(name, wrap180(h - used)) for name, h in others]
            agree = max(abs(wrap180(h1 - h2)) for _, h1 in others for _, h2 in others)
            if all(abs(d) > a.handback_deg for _, d in offs) and agree <= a.handback_deg:
                name, d = offs[0]
                reason = f"{name} {d:+.1f} deg from it"
        if not reason:
            return False
        self.handbacks += 1
        self.handback_reason = reason
        log.critical("FDI heading: substitute not trusted (%s): yaw handed back to the "
                     "pilot", reason)
        return True

    def _set_state(self, state: str) -> None:
        if state == self.state:
            return
        severity, text = STATE_TEXT[state]
        if state == "mode":
            mode = self.mode if self.mode is not None else -1
            text = text.format(mode=_SUB_MODE_NAMES.get(mode, str(mode)))
        log.info("ardusub: %s", text)
        self.output.send_statustext(severity, text)
        if (self.state == STEERING and state in _RELEASE_ON
                and self.acfg.output == "rc_override"):
            self._send_rc(rc_override_channels(self.acfg, None))  # the channels back to RC
            self.rc_releases += 1
        self.state = state

    # -- outputs ------------------------------------------------------------------------

    def _send_rc(self, channels: tuple[int, ...]) -> None:
        self.tx.append(json.dumps({"rc": list(channels)}, separators=(",", ":")).encode())
        if self.router is not None:
            self.router.send_rc_channels_override(channels, target_system=self.vehicle)

    def _send_command(self, x: int, y: int, z: int, r: int, buttons: int,
                      ext: mio.ManualControlExt) -> None:
        """The period's command. Live, under :attr:`PilotInput.lock`: the bridge steers with
        yaw ``r`` from now on, and the frame carries the buttons the vehicle last got (the
        period's newest pilot frame's but for an edge sent on since: :class:`PilotInput`)."""
        pilot = self.pilot
        with pilot.lock if pilot is not None else contextlib.nullcontext():
            if pilot is not None:
                pilot.steering, pilot.r = True, r
                buttons, b2 = pilot.wire
                ext = ext._replace(buttons2=b2)
            if self.acfg.output == "rc_override":
                self._send_rc(rc_override_channels(self.acfg, (x, y, z, r)))
            else:
                line: dict[str, Any] = {"mc": [x, y, z, r, buttons]}
                if ext != _NO_EXT:
                    line["ext"] = list(ext.values())
                self.tx.append(json.dumps(line, separators=(",", ":")).encode())
                self.output.send_manual_control(self.vehicle, x, y, z, r, buttons, ext)
        self.sent += 1

    def _yield_to_pilot(self) -> None:
        """Not steering: the pilot's frames pass unchanged from now on."""
        if self.pilot is not None:
            with self.pilot.lock:
                self.pilot.steering = False

    def step(self, frames: list[bytes] | None = None) -> dict[str, Any]:
        """One period: heading, heartbeat and pilot in (``frames``, default the inbox's);
        controller; MANUAL_CONTROL or RC_CHANNELS_OVERRIDE out when the bridge steers (module
        docstring); operator telemetry."""
        dt = self.cfg.period_s
        self.tx = []
        frames = self._scan_pilot(self.inbox.take() if frames is None else frames)
        meas, yaw_att, rate, hb, pilot = self._absorb(frames)
        if hb is not None:
            self.armed, self.mode = hb
            self._hb_age = 0.0
        elif self._hb_age is not None:
            self._hb_age += dt
        if pilot is not None:
            self._pilot_axes, self._pilot_age = pilot, 0.0
        else:
            self._pilot_age += dt
        was_pilot = self._pilot_has
        pilot_yaw = self._pilot_axes is not None and self._pilot_yaw(dt)
        cmd, dec = self.ctl.step(meas, dt, yaw_rate_dps=rate)
        if was_pilot and not pilot_yaw and dec.heading_used is not None:  # handed back
            self.ctl.setpoint_deg = dec.heading_used % 360.0
            self.ctl.pid.reset()
            log.info("pilot yaw centred %.1f s: holding %.1f deg", self.acfg.pilot_release_s,
                     self.ctl.setpoint_deg)
        gate = self._gate()
        if self._supervise(dec, meas, yaw_att, dt) and gate == STEERING:
            gate = HANDBACK
        state = "pilot" if gate == STEERING and pilot_yaw else gate
        self._set_state(state)
        steering = state == STEERING
        x, y, z, r = manual_control_axes(cmd)
        buttons, ext = 0, _NO_EXT
        if self._pilot_axes is not None and self._pilot_fresh():
            x, y, z, pr, buttons = self._pilot_axes  # the pilot's other axes, unchanged
            ext = self._pilot_ext  # and buttons2, s, t, aux1-6
            if not steering:
                r = pr
        if steering:
            self._send_command(x, y, z, r, buttons, ext)
        else:
            self._yield_to_pilot()
            # Not ours: the yaw the vehicle gets is the pilot's (0 without one), and that is
            # the detector's next input; the PID does not wind up meanwhile.
            if not self._pilot_fresh():
                r = 0
            self.ctl.command = ThrusterCommand(r / 10.0, -r / 10.0)
            self.ctl.pid.reset()
        self.states[state] += 1
        rec = epoch_record(self.t, None, meas, self.ctl.setpoint_deg, cmd, dec, self.ctl.action)
        rec["ardusub"] = state
        rec["r_sent"] = r if steering else None
        if self.acfg.heading == "raw_compass":
            rec["heading_attitude"] = None if yaw_att is None else round(yaw_att, 4)
        if self.acfg.gyro != "none":
            rec["yaw_rate"] = None if rate is None else round(rate, 4)
        self.t += dt
        self.operator(rec)
        if self.on_epoch is not None:
            self.on_epoch(rec)
        return rec


class NullOutput:
    """A :class:`~firmware_host.runtime.mavout.MavlinkOutput` that sends nothing (a replay)."""

    def send_heartbeat(self) -> None:
        """Nothing."""

    def send_statustext(self, severity: int, text: str) -> None:
        """Nothing."""

    def request_mode(self, target_system: int, mode: str, vehicle: str = "rover") -> None:
        """Nothing."""

    def send_gps_input(self, fix: mio.GpsInputFix) -> None:
        """Nothing."""

    def send_named_value(self, name: str, value: float) -> None:
        """Nothing."""

    def send_manual_control(self, target_system: int, x: int, y: int, z: int, r: int,
                            buttons: int = 0, ext: mio.ManualControlExt | None = None) -> None:
        """Nothing."""

    def counters(self) -> dict[str, int]:
        return {}

    def close(self) -> None:
        """Nothing."""


TICK = "ardusub tick"
"""Recorder channel: one ``{"k": step, "t": seconds}`` record at the start of each step."""
RX = "ardusub rx"
"""Recorder channel: each frame the step took from the inbox (one record per frame)."""
TX = "ardusub tx"
"""Recorder channel: each command the step sent (``RovAutopilotLoop.tx`` lines)."""


class ArduSubRovVehicle(RovVehicleBase):
    """The ROV through an ArduSub autopilot as a vehicle of the runtime (module docstring).

    Needs the runner's router (a ``[mavlink]`` table): ATTITUDE (and the raw compass) in,
    MANUAL_CONTROL or RC_CHANNELS_OVERRIDE out. With a flight recorder, each step writes a
    mark on :data:`TICK`, then the frames it took on :data:`RX` and its commands on
    :data:`TX`: ``fdi-bridge replay`` re-runs the steps on exactly those frames
    (:func:`firmware_host.rov.replay.replay_ardusub`). The step marks, records,
    ``check``/``idle_s``/``finish`` and the summary's frame are
    :class:`~firmware_host.rov.base.RovVehicleBase`'s.
    """

    name = "rov-ardusub"

    def __init__(self, cfg: RovConfig, *, ft: bool = True, vehicle_system_id: int | None = None,
                 on_epoch: Callable[[dict[str, Any]], None] | None = None) -> None:
        super().__init__(cfg)
        self.ft = ft
        self.vehicle_system_id = (cfg.ardusub.vehicle_system_id if vehicle_system_id is None
                                  else vehicle_system_id)
        self.on_epoch = on_epoch
        self.loop: RovAutopilotLoop | None = None
        self._rx: Tap | None = None
        self._tx: Tap | None = None

    def ports(self) -> list[PortSpec]:
        return []  # the router's autopilot link is the vehicle's

    def mavlink(self) -> MavlinkSpec | None:
        return None

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
        if ctx.router is None:
            raise ConfigError("(config)", "mavlink", "a [mavlink] table: the ArduSub ROV's "
                              "heading comes from the autopilot", "none")
        self.loop = RovAutopilotLoop(self.cfg, ctx.router, ft=self.ft,
                                     vehicle_system_id=self.vehicle_system_id,
                                     on_epoch=self.on_epoch)  # before the router starts
        self.epochs = ctx.epochs
        url = ctx.router.cfg.autopilot.url
        self.tick = ctx.tap(TICK, "", 0, "tx")
        self._rx = ctx.tap(RX, url, 0, "rx")
        self._tx = ctx.tap(TX, url, 0, "tx")
        self.t0 = ctx.clock()

    def start_replay(self, epochs: EpochLog) -> None:
        """No router: the steps get their frames from :meth:`step_frames` (a replay)."""
        self.loop = RovAutopilotLoop(self.cfg, None, ft=self.ft,
                                     vehicle_system_id=self.vehicle_system_id,
                                     on_epoch=self.on_epoch, output=NullOutput())
        self.epochs = epochs

    def step(self, t: float) -> int:
        assert self.loop is not None
        self._mark(t)
        frames = self.loop.inbox.take()
        if self._rx is not None:
            for raw in frames:
                self._rx(raw)
        self.step_frames(frames)
        if self._tx is not None:
            for line in self.loop.tx:
                self._tx(line)
        return 1

    def step_frames(self, frames: list[bytes]) -> dict[str, Any]:
        """One step on ``frames`` (live: the inbox's; a replay: the recorded ones)."""
        assert self.loop is not None
        self.steps += 1
        rec = self.loop.step(frames)
        self._account(rec)
        self.epochs.write(rec)
        return rec

    def _summary_fields(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.loop is not None:
            lp = self.loop
            if lp.heading is not None and lp.autopilot is not None and lp.pilot is not None:
                out["attitude_received"] = lp.heading.received
                out["heartbeat_received"] = lp.autopilot.received
                out["pilot_received"] = lp.pilot.received
                out["gcs_heartbeats_received"] = lp.pilot.gcs_heartbeats
                out["button_edges_sent"] = lp.pilot.edges_sent
            if lp.compass is not None:
                out["compass_received"] = lp.compass.received
            if lp.compass_slow_hz is not None:
                out["compass_slow_hz"] = lp.compass_slow_hz
            out["frames_taken"] = dict(sorted(lp.taken.items()))
            out["inputs_rejected"] = dict(sorted(lp.rejected.items()))
            out["heading"] = lp.acfg.heading
            out["output"] = lp.acfg.output
            out["manual_control_sent" if lp.acfg.output == "manual_control"
                else "rc_override_sent"] = lp.sent
            if lp.acfg.output == "rc_override":
                out["rc_releases"] = lp.rc_releases
            out["pilot_takeovers"] = lp.takeovers
            out["handbacks"] = lp.handbacks
            w = lp.ctl.heading.witness
            out["witness"] = {"warmup_restarts": w.warmup_restarts, "maneuvers": w.maneuvers,
                              "bias_dps": round(w.bias, 4)}
            out["ardusub_states"] = dict(sorted(lp.states.items()))
        return out
