"""MAVLink passthrough: forward every packet byte for byte, and add the bridge's own component.

The router sits on the companion link between the autopilot and one or more ground stations
(``[mavlink]`` in the vehicle's TOML, :class:`MavlinkConfig`). Each packet a link delivers is
framed (:mod:`drivers.mavlink.framer`: corrupt bytes counted and dropped there) and sent, bytes
unchanged and in order, to every *other* endpoint, except that a message with a target system
goes only to endpoints where that system (or system + component) has been seen, as
mavlink-router and the MAVLink routing rules do. A ``.tlog`` records all of it.

The bridge's own component (``system_id``/``component_id``, default 1/191) sends a
MAV_TYPE_ONBOARD_CONTROLLER heartbeat, STATUSTEXT and NAMED_VALUE_FLOAT at configured rates,
GPS_INPUT / MANUAL_CONTROL for the pipelines, and answers the parameter protocol from a
:class:`~firmware_host.mavlink.params.ParamStore`. With signing on a ground-station link, unsigned
(or badly signed, or replayed) COMMAND_LONG / COMMAND_INT / PARAM_SET addressed to the bridge's
component are refused and counted; reads (PARAM_REQUEST_*) stay open.

Forwarding is event-driven: one ``select`` (epoll) waits on every link's descriptors, a
wake-up socket for the pipelines' packets, and the next periodic job's deadline. A datagram is
framed, routed and written to its destinations before the next one is read, so a packet waits
for nothing but the packets ahead of it. A write that the kernel refuses (buffer full) puts the
packet in the destination's bounded queue, and the loop waits for that link to become writable;
when a queue is full the oldest packet is dropped and counted. Reads are capped per endpoint
and round (``read_burst``), so a flood on one link stalls neither the other direction nor the
thread that runs the detectors (that thread only hands packets over, through
:meth:`Router.send_gps_input` and friends, and never blocks on a socket). Packets for a UDP
server endpoint nobody has spoken to yet are dropped and counted (``no_peer``): there is
nowhere to send them, and a ground station that connects later wants fresh telemetry, not a
backlog. The bridge's own packets never wait behind forwarded ones: the loop takes them between
any two datagrams, and an endpoint keeps them in a queue of their own that is written first.
Routes (a system/component seen on an endpoint) are forgotten after ``route_timeout_s`` of
silence. Drops are counted per endpoint (queues, send buffers, the kernel's receive drops).

The loop owns time: ``clock`` (monotonic seconds) is an argument; :meth:`Router.tick` runs the
periodic jobs for a given time so tests drive it with
:class:`~firmware_host.runtime.loop.FakeClock`.
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import selectors
import shutil
import socket
import stat
import struct
import threading
import time
from collections import deque
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from drivers.mavlink import io as mio
from drivers.mavlink.framer import MavFrame, MavFramer, frame_target, signature_ok
from drivers.mavlink.links import Link, TcpServerLink, UdpPeerLink, UdpServerLink, open_link
from fdi.errors import ConfigError, PortError
from firmware_host.mavlink.params import ParamStore
from firmware_host.runtime.config import (
    BridgeConfig,
    bridge_config,
    load_bridge_file,
    mavlink_config,
)
from firmware_host.runtime.config_mavlink import EndpointConfig as EndpointConfig  # re-exported
from firmware_host.runtime.config_mavlink import MavlinkConfig

log = logging.getLogger("fdi_bridge.router")

Clock = Callable[[], float]

# ---------------------------------------------------------------------------------------------
# Configuration


def load_mavlink_config(path: str | Path) -> MavlinkConfig:
    """The ``[mavlink]`` table of a file or preset (its defaults when absent)."""
    return mavlink_config(load_bridge_file(path))


def load_vehicle_config(path: str | Path) -> BridgeConfig | None:
    """The rover's view of the file at ``path`` when it has a ``[rover]`` table (the
    one-process mode), else None."""
    bf = load_bridge_file(path)
    return bridge_config(bf) if bf.rover is not None else None


def load_signing_key(path: str | Path) -> bytes:
    """A 32-byte MAVLink signing key from a file holding 64 hexadecimal characters.

    MAVProxy's and QGroundControl's passphrase keys are ``sha256(passphrase)``; write that as
    hex. The file must be readable and writable by its owner only (mode 0600 or stricter: no
    bit for the group or others, as ssh asks of a private key) and must not sit inside a git
    working tree (a key is never committed).
    """
    p = Path(path).expanduser()
    try:
        mode = p.stat().st_mode
        text = p.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(str(p), "(file)", "a readable key file", str(err)) from err
    if mode & 0o077:
        raise ConfigError(str(p), "(mode)", "a file only its owner can read (chmod 600)",
                          f"mode {stat.S_IMODE(mode):04o}, open to its group or others")
    for parent in p.resolve().parents:
        if (parent / ".git").exists():
            raise ConfigError(
                str(p), "(location)", "a path outside any git repository", str(parent)
            )
    try:
        key = bytes.fromhex(text)
    except ValueError as err:
        raise ConfigError(
            str(p), "(key)", "64 hexadecimal characters", f"{len(text)} chars"
        ) from err
    if len(key) != 32:
        raise ConfigError(str(p), "(key)", "64 hexadecimal characters", f"{len(text)} chars")
    return key


# ---------------------------------------------------------------------------------------------
# .tlog recorder


class TlogWriter:
    """QGroundControl ``.tlog``: 8-byte big-endian µs (Unix time) before each packet; rotated.

    A full or read-only disk never stops forwarding: the failure is logged once, counted
    (``write_errors``, and every packet not written in ``lost_packets``), the file is closed,
    and a new file is tried every :data:`TLOG_RETRY_S` (monotonic), so writing resumes by
    itself when space returns. The directory is kept under ``dir_max_bytes`` (oldest
    ``fdi-*.tlog`` deleted first) and the disk above ``min_free_bytes`` (the oldest files go
    first; when that is not enough the tlog pauses, counted, and retries).
    """

    def __init__(self, directory: str | Path, max_bytes: int, wall_clock: Clock = time.time,
                 *, dir_max_bytes: int = 0, min_free_bytes: int = 0,
                 clock: Clock = time.monotonic) -> None:
        self.dir = Path(directory)
        self.max_bytes = max_bytes
        self.dir_max_bytes = dir_max_bytes
        self.min_free_bytes = min_free_bytes
        self.wall_clock = wall_clock
        self.clock = clock
        self.retry_s = TLOG_RETRY_S
        self.files: list[Path] = []
        self._f: Any = None
        self._size = 0
        self._n = 0
        self.packets = 0
        self.write_errors = 0
        self.lost_packets = 0
        self.deleted_files = 0
        self._unflushed = 0
        self._failing = False
        self._retry_at = 0.0
        self._open()

    def _open(self) -> None:
        if self._f is not None:
            self._flush_buffer()
        self._close_file()
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
            self._make_room()
            stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime(self.wall_clock()))
            path = self.dir / f"fdi-{stamp}-{self._n:03d}.tlog"
            self._f = open(path, "ab")  # noqa: SIM115  (kept open across calls, closed in close())
        except OSError as err:
            self._fail(err)
            return
        self._n += 1
        self.files.append(path)
        self._size = 0
        self._unflushed = 0
        if self._failing:
            log.warning("tlog: writing again (%s)", path)
            self._failing = False

    def _make_room(self) -> None:
        """Delete the oldest tlogs while the directory or the disk is over its limit."""
        if not (self.dir_max_bytes or self.min_free_bytes):
            return
        old = sorted(self.dir.glob("fdi-*.tlog"), key=lambda q: q.stat().st_mtime)
        total = sum(q.stat().st_size for q in old)
        while old:
            free = shutil.disk_usage(self.dir).free
            over_dir = self.dir_max_bytes and total + self.max_bytes > self.dir_max_bytes
            if not over_dir and free - self.max_bytes >= self.min_free_bytes:
                break
            victim = old.pop(0)
            total -= victim.stat().st_size
            victim.unlink()
            self.deleted_files += 1
        if shutil.disk_usage(self.dir).free < self.min_free_bytes:
            raise OSError(errno.ENOSPC, "less free space than tlog_min_free_bytes")

    def _fail(self, err: OSError) -> None:
        self.write_errors += 1
        self.packets -= self._unflushed  # a write error loses the buffer with the file
        self.lost_packets += self._unflushed
        self._unflushed = 0
        if not self._failing:
            log.warning("tlog: not written (%s); forwarding goes on, a new file is tried every "
                        "%.0f s", err.strerror or err, self.retry_s)
        self._failing = True
        self._close_file()
        self._retry_at = self.clock() + self.retry_s

    def _close_file(self) -> None:
        f, self._f = self._f, None
        if f is not None:
            with contextlib.suppress(OSError):
                f.close()

    def write(self, raw: bytes, t_s: float | None = None) -> None:
        if self._f is None:
            if self.clock() < self._retry_at:
                self.lost_packets += 1
                return
            self._open()
            if self._f is None:
                self.lost_packets += 1
                return
        elif self._size + 8 + len(raw) > self.max_bytes and self._size > 0:
            self._open()
            if self._f is None:
                self.lost_packets += 1
                return
        t = self.wall_clock() if t_s is None else t_s
        try:
            self._f.write(struct.pack(">Q", int(t * 1e6)) + raw)
        except OSError as err:
            self.lost_packets += 1
            self._fail(err)
            return
        self._size += 8 + len(raw)
        self.packets += 1
        self._unflushed += 1

    def flush(self) -> None:
        """Push the buffer to the file (the router does it at least once a second); below
        ``min_free_bytes`` free, rotate (the oldest files deleted) or pause."""
        if not self._flush_buffer() or not self.min_free_bytes:
            return
        try:
            low = shutil.disk_usage(self.dir).free < self.min_free_bytes
        except OSError:
            low = False
        if low:
            self._open()

    def _flush_buffer(self) -> bool:
        """Flush; False when there is no file or the flush failed (counted)."""
        if self._f is None:
            return False
        try:
            self._f.flush()
        except OSError as err:
            # What sat in the buffer is lost with the file (counted as such).
            self.packets -= self._unflushed
            self.lost_packets += self._unflushed
            self._unflushed = 0
            self._fail(err)
            return False
        self._unflushed = 0
        return True

    def close(self) -> None:
        self._flush_buffer()
        self._close_file()

    def counters(self) -> dict[str, int]:
        return {"tlog_packets": self.packets, "tlog_write_errors": self.write_errors,
                "tlog_lost_packets": self.lost_packets, "tlog_deleted_files": self.deleted_files}


TLOG_RETRY_S = 5.0


# ---------------------------------------------------------------------------------------------
# Router


@dataclass
class EndpointStats:
    rx_packets: int = 0
    tx_packets: int = 0
    dropped_queue_full: int = 0  # forwarded packets dropped (the oldest) from a full queue
    dropped_own: int = 0  # the bridge's own packets dropped from a full queue of their own
    no_peer: int = 0  # packets for this endpoint while nobody was there to take them
    unroutable: int = 0  # targeted packets from here that no other endpoint could take
    loop_guard: int = 0  # packets not sent here because their source was seen here
    filtered_in: int = 0  # packets from here dropped by block_in
    filtered_out: int = 0  # packets not sent here by allow_out / block_out
    rate_limited: int = 0  # packets not sent here beyond max_out_pps


class Endpoint:
    """A link, its framers (one per stream), its outgoing queue and what it has seen."""

    def __init__(self, name: str, link: Link, *, is_gcs: bool, signing: bool, queue: int,
                 cfg: EndpointConfig | None = None):
        self.name = name
        self.link = link
        self.is_gcs = is_gcs
        self.signing = signing
        self.queue: deque[bytes] = deque()  # forwarded packets waiting for the link
        self.own_queue: deque[bytes] = deque()  # the bridge's own, written before the others
        self.queue_max = queue
        self.framers: dict[Hashable, MavFramer] = {}
        # Routes: what was heard here, with when (router clock); forgotten after
        # ``route_timeout_s`` of silence (Router._expire_routes).
        self.seen_sys: dict[int, float] = {}
        self.seen: dict[tuple[int, int], float] = {}
        self.stats = EndpointStats()
        c = cfg or EndpointConfig("")
        self.allow_unsigned = c.ids("allow_unsigned")
        self.block_in = c.ids("block_in")
        allow_out, block_out = c.ids("allow_out"), c.ids("block_out")
        self.filter_out: Callable[[int], bool] | None = None
        if allow_out or block_out:
            self.filter_out = lambda m: (not allow_out or m in allow_out) and m not in block_out
        self.max_out_pps = c.max_out_pps
        self._tokens = c.max_out_pps
        self._tokens_t = 0.0
        self.cfg = c
        # A TCP server only accepts: each client becomes an endpoint of its own (``clients``),
        # with its own routes, queue and counters, so one stalled client starves nobody.
        # A ground station's UDP server the same way: each peer (address) is an endpoint.
        self.server = isinstance(link, TcpServerLink) or (is_gcs and isinstance(link,
                                                                               UdpServerLink))
        self.parent: Endpoint | None = None
        self.children: list[Endpoint] = []
        self.by_addr: dict[Hashable, Endpoint] = {}
        self.clients = 0
        self.clients_gone = 0
        self.gone_stats = EndpointStats()  # what clients that have gone had counted

    def rate_ok(self, now: float) -> bool:
        """Token bucket of ``max_out_pps`` packets/s (a burst of one second's worth)."""
        rate = self.max_out_pps
        self._tokens = min(rate, self._tokens + (now - self._tokens_t) * rate)
        self._tokens_t = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        self.stats.rate_limited += 1
        return False

    def send(self, raw: bytes, own: bool = False) -> None:
        """Write ``raw`` now when nothing waits before it; else queue it behind the others.

        ``own``: one of the bridge's own packets (GPS_INPUT, heartbeat, STATUSTEXT, answers).
        They wait only behind each other, in a queue of their own written first, never behind
        forwarded traffic; a full queue drops forwarded packets, never the bridge's own for
        them (the oldest own packet goes only when ``queue_packets`` of them wait).
        """
        if self.server:  # its clients are endpoints of their own: to each of them
            for child in self.children:
                child.send(raw, own)
            return
        if self.own_queue or (self.queue and not own):
            self.enqueue(raw, own)
        elif not self.link.has_peer():
            self.stats.no_peer += 1
        elif self.link.write(raw):
            self.stats.tx_packets += 1
        else:
            self.enqueue(raw, own)

    def enqueue(self, raw: bytes, own: bool = False) -> None:
        q = self.own_queue if own else self.queue
        if len(q) >= self.queue_max:
            q.popleft()
            if own:
                self.stats.dropped_own += 1
            else:
                self.stats.dropped_queue_full += 1
        q.append(raw)

    def blocked(self) -> bool:
        """True when packets or bytes wait for the link to become writable."""
        return bool(self.queue or self.own_queue) or self.link.backlog()

    def flush(self) -> None:
        """Write what waits, the bridge's own packets first, until the link refuses."""
        link = self.link
        if link.backlog():
            link.flush()
        if not link.has_peer():
            self.stats.no_peer += len(self.own_queue) + len(self.queue)  # the peer went away
            self.own_queue.clear()
            self.queue.clear()
        for q in (self.own_queue, self.queue):
            while q:
                if not link.write(q[0]):
                    return
                q.popleft()
                self.stats.tx_packets += 1

    def accepts(self, target: tuple[int, int]) -> bool:
        """mavlink-router's rule for a message addressed to ``target`` (system, component)."""
        sysid, compid = target
        if sysid == 0:
            return True
        if compid == 0:
            return sysid in self.seen_sys
        return (sysid, compid) in self.seen


@dataclass
class RouterStats:
    forwarded: int = 0
    no_destination: int = 0  # broadcasts nobody could take (no other peer, or loop guard)
    for_bridge: int = 0
    bad_crc: int = 0
    dropped_bytes: int = 0
    unchecked: int = 0
    refused_unsigned: int = 0  # unsigned packets dropped from a signing link
    unsigned_allowed: int = 0  # unsigned packets of allow_unsigned passed from a signing link
    bad_signature: int = 0
    replayed_signature: int = 0  # not newer than its stream's last packet
    old_stream_refused: int = 0  # a new stream more than a minute behind our timestamp
    signing_state_errors: int = 0  # failed writes of the signing state file
    params_set: int = 0
    params_rejected: int = 0
    own_sent: int = 0
    statustext_dropped: int = 0
    command_sent: int = 0  # the bridge's COMMAND_LONGs (first attempts and retries)
    command_accepted: int = 0
    command_refused: int = 0  # COMMAND_ACK with a result other than ACCEPTED / IN_PROGRESS
    command_unacked: int = 0  # no COMMAND_ACK after command_retries attempts
    ftp_nak: int = 0
    routes_expired: int = 0  # (system, component) routes forgotten after route_timeout_s


_COMMAND_IDS = frozenset(
    {mio.message_id("COMMAND_LONG"), mio.message_id("COMMAND_INT"), mio.message_id("PARAM_SET")}
)
_PARAM_READ_IDS = frozenset(
    {mio.message_id("PARAM_REQUEST_LIST"), mio.message_id("PARAM_REQUEST_READ")}
)
_FOR_BRIDGE_IDS = _COMMAND_IDS | _PARAM_READ_IDS
_COMMAND_ACK = mio.message_id("COMMAND_ACK")
_FTP = mio.message_id("FILE_TRANSFER_PROTOCOL")
_FTP_NAK = 129
_FTP_ERR_FAIL = 1
_FTP_ERR_FILE_NOT_FOUND = 10
_FTP_OPEN_RO = 4
SIGNING_NEW_STREAM_WINDOW = 6_000_000  # one minute in signing units (10 µs)
SIGNING_STATE_EVERY_S = 30.0


@dataclass
class _PendingCommand:
    """A COMMAND_LONG of the bridge waiting for its COMMAND_ACK (resent until answered)."""

    command: int
    what: str  # for the operator: "mode HOLD"
    encode: Callable[[], bytes]
    attempts: int = 1
    due: float | None = None  # set by the loop thread at its next tick


class Router:
    """The passthrough and the bridge's own component (see the module docstring)."""

    def __init__(
        self,
        cfg: MavlinkConfig,
        *,
        params: ParamStore | None = None,
        clock: Clock = time.monotonic,
        wall_clock: Clock = time.time,
        signing_key: bytes | None = None,
        tlog: TlogWriter | None = None,
    ) -> None:
        self.cfg = cfg
        self.clock = clock
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.endpoints: list[Endpoint] = []
        self.tlog: TlogWriter | None = None
        self.params = params if params is not None else ParamStore()
        self.stats = RouterStats()
        self._offsets = mio.target_offsets()
        self._lock = threading.Lock()
        self._own = mio.MavPacker(cfg.system_id, cfg.component_id)
        # The bridge's MANUAL_CONTROL / RC_CHANNELS_OVERRIDE: ArduSub takes them only from its
        # GCS's system id (GCS::sysid_is_gcs, MAV_GCS_SYSID); the component is the bridge's own,
        # so the pilot's (GCS, 190) stream and the bridge's stay apart (sequence numbers).
        self._pilot = mio.MavPacker(cfg.pilot_system_id, cfg.component_id)
        if any(g.signing for g in cfg.gcs) and signing_key is None:
            signing_key = load_signing_key(cfg.signing_key_file)
        self._key = signing_key
        if signing_key is not None:
            self._own.setup_signing(signing_key, link_id=0)
            self._pilot.setup_signing(signing_key, link_id=1)  # an ArduSub that checks signatures
        self._sig_last: dict[tuple[int, int, int], int] = {}  # (link id, sys, comp) -> ts
        self._sig_local = 0  # our signing timestamp: max(clock, every accepted timestamp)
        self._sig_state_path: Path | None = None
        self._sig_dirty = False
        if signing_key is not None:
            state = cfg.signing_state_file or (
                f"{cfg.signing_key_file}.state" if cfg.signing_key_file else "")
            self._sig_state_path = Path(state).expanduser() if state else None
            self._load_signing_state()
        try:
            a = cfg.autopilot
            ap = open_link(a.url, a.baud, cfg.reconnect_max_s, peer_timeout_s=a.peer_timeout_s,
                           accept_any=a.accept_any)
            self.autopilot = Endpoint(
                a.name or "autopilot", ap, is_gcs=False, signing=False,
                queue=cfg.queue_packets, cfg=a,
            )  # fmt: skip
            self.endpoints.append(self.autopilot)
            for i, g in enumerate(cfg.gcs):
                link = open_link(g.url, g.baud, cfg.reconnect_max_s,
                                 peer_timeout_s=g.peer_timeout_s, accept_any=g.accept_any)
                self.endpoints.append(
                    Endpoint(g.name or f"gcs{i}", link, is_gcs=True, signing=g.signing,
                             queue=cfg.queue_packets, cfg=g)
                )  # fmt: skip
        except PortError:
            self.close()  # the links opened so far (a busy port is an EndpointError: exit 2)
            raise
        self.tlog = tlog
        if tlog is None and cfg.tlog_dir:
            self.tlog = TlogWriter(cfg.tlog_dir, cfg.tlog_max_bytes, wall_clock,
                                   dir_max_bytes=cfg.tlog_dir_max_bytes,
                                   min_free_bytes=cfg.tlog_min_free_bytes, clock=clock)
        self._pending: _PendingCommand | None = None
        self._any_clients = False
        self._next_reap = 0.0
        self._sel = selectors.DefaultSelector()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._sel.register(self._wake_r, selectors.EVENT_READ, None)
        self._registered: dict[int, tuple[int, Endpoint]] = {}
        self._outbox: deque[tuple[bytes, Endpoint | None]] = deque(maxlen=cfg.queue_packets)
        self._texts: deque[tuple[int, str]] = deque(maxlen=64)
        self._values: dict[str, float] = {}
        self._listeners: dict[int, list[Callable[[MavFrame], None]]] = {}
        self._intercepts: dict[int, list[Callable[[MavFrame], bool]]] = {}
        self._t0 = clock()
        self._next_hb = self._t0
        self._next_stats = self._t0
        self._text_tokens = cfg.statustext_per_s
        self._last_tick = self._t0
        self._next_flush = self._t0 + 1.0
        self._next_slow = self._t0 + SIGNING_STATE_EVERY_S
        self._next_report = self._t0 + cfg.report_stats_s
        self._now = self._t0  # the clock at this round's reads: when a route was last heard
        self._next_expiry = self._t0 + 1.0

    # -- thread-safe API for the pipelines -------------------------------------------------

    def _post(self, raw: bytes, dest: Endpoint | None) -> None:
        self._outbox.append((raw, dest))
        self._wake()

    def _wake(self) -> None:
        with contextlib.suppress(OSError):  # wake-up socket full: the loop is awake anyway
            self._wake_w.send(b"\0")

    def send_gps_input(self, fix: mio.GpsInputFix) -> bytes:
        """GPS_INPUT to the autopilot (rover: the corrected fix)."""
        with self._lock:
            raw = self._own.send_gps_input(fix)
        self._post(raw, self.autopilot)
        return raw

    def send_manual_control(
        self, x: int, y: int, z: int, r: int, buttons: int = 0, target_system: int | None = None,
        ext: mio.ManualControlExt | None = None,
    ) -> bytes:
        """MANUAL_CONTROL to the autopilot from the pilot's (GCS) system id and the bridge's
        component id (ArduSub), with a pilot's extension fields ``ext``.

        ``target_system`` is the vehicle's system id (default: the bridge's own, as on a
        companion computer that shares the vehicle's id).
        """
        target = self.cfg.system_id if target_system is None else target_system
        with self._lock:
            raw = self._pilot.send_manual_control(target, x, y, z, r, buttons, ext)
        self._post(raw, self.autopilot)
        return raw

    def send_rc_channels_override(self, channels: tuple[int, ...],
                                  target_system: int | None = None) -> bytes:
        """RC_CHANNELS_OVERRIDE (18 values) to the autopilot from the pilot's (GCS) system id:
        ArduPilot takes it only from ``MAV_GCS_SYSID``, as MANUAL_CONTROL."""
        target = self.cfg.system_id if target_system is None else target_system
        with self._lock:
            raw = self._pilot.send_rc_channels_override(target, 1, channels)
        self._post(raw, self.autopilot)
        return raw

    def request_mode(
        self, mode: str, vehicle: str = "rover", target_system: int | None = None
    ) -> bytes:
        """COMMAND_LONG DO_SET_MODE (``"HOLD"``) to the autopilot (system ``target_system``)."""
        target = self.cfg.system_id if target_system is None else target_system

        def encode() -> bytes:
            with self._lock:
                return self._own.request_mode(target, mode, vehicle)

        raw = encode()
        with self._lock:
            self._pending = _PendingCommand(mio.MAV_CMD_DO_SET_MODE, f"mode {mode}", encode)
            self.stats.command_sent += 1
        self._post(raw, self.autopilot)
        return raw

    def post_statustext(self, severity: int, text: str) -> None:
        """Queue a STATUSTEXT (sent at most ``statustext_per_s``; oldest dropped when full)."""
        with self._lock:
            if len(self._texts) == self._texts.maxlen:
                self.stats.statustext_dropped += 1
            self._texts.append((severity, text))
        self._wake()

    def listen(self, message: str, callback: Callable[[MavFrame], None]) -> None:
        """Call ``callback(frame)`` (in the router's thread) for each ``message`` (a name such as
        ``"ATTITUDE"``) that arrives from the autopilot. Register before :meth:`start`; the
        callback must be quick (it runs in the forwarding path) and must not raise."""
        self._listeners.setdefault(mio.message_id(message), []).append(callback)

    def intercept(self, message: str, callback: Callable[[MavFrame], bool]) -> None:
        """Hand each ``message`` from a ground station to ``callback`` (router thread) before
        forwarding it; it is forwarded only when every callback returns True (the ArduSub ROV
        merges the pilot's MANUAL_CONTROL with its yaw). Register before :meth:`start`."""
        self._intercepts.setdefault(mio.message_id(message), []).append(callback)

    def set_named_value(self, name: str, value: float) -> None:
        """Latest value of a detector statistic, sent as NAMED_VALUE_FLOAT at ``stats_hz``."""
        with self._lock:
            self._values[name] = float(value)

    # -- the loop ----------------------------------------------------------------------------

    def _sync_selector(self) -> bool:
        """Register each link's descriptors: read always, write while it is blocked.

        Returns True when some endpoint has no descriptor to wait on (``loop://``): the loop
        then polls it every few milliseconds.
        """
        want: dict[int, tuple[int, Endpoint]] = {}
        polled = False
        for ep in self.endpoints:
            fds = ep.link.filenos()
            if not fds and not getattr(ep.link, "passive", False):
                polled = True
            for fd in fds:
                want[fd] = (selectors.EVENT_READ, ep)
            if ep.blocked():
                for fd in ep.link.write_filenos():
                    want[fd] = (selectors.EVENT_READ | selectors.EVENT_WRITE, ep)
        registered = self._registered
        if want == registered:
            return polled
        for fd in list(registered):
            if fd not in want:
                with contextlib.suppress(KeyError, ValueError, OSError):
                    self._sel.unregister(fd)
                del registered[fd]
        for fd, entry in want.items():
            old = registered.get(fd)
            if old == entry:
                continue
            if old is None:
                self._sel.register(fd, entry[0], entry[1])
            else:
                self._sel.modify(fd, entry[0], entry[1])
            registered[fd] = entry
        return polled

    def _next_due(self, now: float) -> float:
        """Seconds until the next periodic job (heartbeat, statistics, a paced STATUSTEXT)."""
        due = self._next_hb
        if self.cfg.stats_hz > 0 and self._values:
            due = min(due, self._next_stats)
        if self._texts:
            rate = self.cfg.statustext_per_s
            due = min(due, now + max(0.0, 1.0 - self._text_tokens) / rate)
        return max(0.0, due - now)

    def poll(self, timeout_s: float = 0.05) -> None:
        """One round: wait for input (at most ``timeout_s``), route, send, run periodic jobs.

        The wait ends at the first of: a datagram or bytes on any link, a link that was blocked
        becoming writable, a packet handed over by a pipeline thread, the next periodic job.
        """
        polled = self._sync_selector()
        now = self.clock()
        wait = min(timeout_s, self._next_due(now))
        if polled:
            wait = min(wait, 0.005)
        if self._outbox:
            wait = 0.0
        events = self._sel.select(wait)
        self._now = self.clock()
        self._drain_outbox()
        done: list[Endpoint] = []
        for key, mask in events:
            ep = key.data
            if ep is None:
                with contextlib.suppress(BlockingIOError):
                    while self._wake_r.recv(4096):
                        pass
                continue
            if mask & selectors.EVENT_WRITE:
                ep.flush()
            if mask & selectors.EVENT_READ and ep not in done:
                done.append(ep)
                self._read(ep)
        if polled:
            for ep in self.endpoints:
                if not ep.link.filenos() and ep not in done and not getattr(
                        ep.link, "passive", False):
                    self._read(ep)
        self._drain_outbox()
        self.tick(self.clock())
        for ep in self.endpoints:
            if ep.blocked():
                ep.flush()
        if self._any_clients:
            now = self.clock()
            if now >= self._next_reap:
                self._next_reap = now + 0.05
                self._reap()

    def _accept(self, server: Endpoint) -> None:
        """New clients of a TCP server: one endpoint each (named ``<server>.<n>``)."""
        link = server.link
        assert isinstance(link, TcpServerLink)
        for client in link.accept_links():
            self._add_client(server, client)

    def _add_client(self, server: Endpoint, link: Link) -> Endpoint:
        server.clients += 1
        ep = Endpoint(f"{server.name}.{server.clients}", link, is_gcs=server.is_gcs,
                      signing=server.signing, queue=self.cfg.queue_packets, cfg=server.cfg)
        ep.parent = server
        self._any_clients = True
        server.children = [*server.children, ep]
        self.endpoints = [*self.endpoints, ep]  # copied: other threads may iterate it
        return ep

    def _read_udp_server(self, server: Endpoint) -> None:
        """A ground station's UDP server: each datagram is routed from its peer's endpoint."""
        link = server.link
        assert isinstance(link, UdpServerLink)
        by_addr = server.by_addr
        route = self._route
        outbox = self._outbox
        for data, addr, boundary in link.read(self.cfg.read_burst):
            src = by_addr.get(addr)
            if src is None or src.parent is None:
                peer = cast(tuple[str, int], addr)
                src = by_addr[addr] = self._add_client(server, UdpPeerLink(link, peer))
            framer = src.framers.get(addr)
            if framer is None:
                framer = src.framers[addr] = MavFramer(on_drop=self._on_drop)
            for frame in framer.feed(data, boundary=boundary):
                route(src, frame)
            if outbox:  # the bridge's own packets never wait for the rest of a burst
                self._drain_outbox()

    def _reap(self) -> None:
        """Drop the endpoints of TCP clients that have gone (their counters fold into the
        server's: ``clients_gone``, and their link errors)."""
        gone = [ep for ep in self.endpoints if ep.parent is not None and not ep.link.has_peer()]
        if not gone:
            return
        for ep in gone:
            parent = ep.parent
            assert parent is not None
            parent.clients_gone += 1
            ep.stats.no_peer += len(ep.queue) + len(ep.own_queue)
            for name, value in ep.stats.__dict__.items():
                setattr(parent.gone_stats, name, getattr(parent.gone_stats, name) + value)
            parent.children = [c for c in parent.children if c is not ep]
            if isinstance(ep.link, UdpPeerLink):
                parent.by_addr.pop(ep.link.addr, None)
            ep.parent = None
        self.endpoints = [ep for ep in self.endpoints if ep not in gone]

    def _read(self, src: Endpoint) -> None:
        if src.server:
            if isinstance(src.link, UdpServerLink):
                self._read_udp_server(src)
            else:
                self._accept(src)
            return
        framers = src.framers
        route = self._route
        outbox = self._outbox
        for data, key, boundary in src.link.read(self.cfg.read_burst):
            framer = framers.get(key)
            if framer is None:
                # A stream (serial, TCP) is joined at an unknown point: it starts resyncing.
                framer = framers[key] = MavFramer(on_drop=self._on_drop, synced=boundary)
            for frame in framer.feed(data, boundary=boundary):
                route(src, frame)
            if outbox:  # the bridge's own packets never wait for the rest of a burst
                self._drain_outbox()

    def _on_drop(self, data: bytes, reason: str) -> None:
        self.stats.dropped_bytes += len(data)
        if reason == "bad_crc":
            self.stats.bad_crc += 1

    def _route(self, src: Endpoint, frame: MavFrame) -> None:
        src.stats.rx_packets += 1
        msgid = frame.msgid
        verified = False
        if src.signing and (frame.signed or msgid not in src.allow_unsigned):
            # A link marked for signing passes only correctly signed, fresh packets, towards
            # the vehicle and anywhere else (MAVLink 2 signing: sig, stream order, 1 min),
            # and unsigned ones of allow_unsigned (a signed one is checked all the same).
            # Unsigned parameter reads addressed to the bridge are answered, not forwarded.
            if not frame.signed and msgid in _PARAM_READ_IDS:
                target = frame_target(frame, self._offsets)
                if target is not None and target[0] != 0 and self._addressed_to_me(target):
                    self.stats.for_bridge += 1
                    self._handle(src, frame, False)
                else:
                    self.stats.refused_unsigned += 1
                return
            if not self._signature_accepted(frame):
                return
            verified = True
        if msgid in src.block_in:
            src.stats.filtered_in += 1
            return
        source = (frame.sysid, frame.compid)
        if not frame.crc_checked:
            self.stats.unchecked += 1
        elif src.signing and not verified:
            self.stats.unsigned_allowed += 1  # allow_unsigned: passed, but teaches no route
        else:  # only a checked (and, on a signing link, signed) packet teaches a route
            now = self._now
            src.seen_sys[frame.sysid] = now
            src.seen[source] = now
        raw = frame.raw
        if self.tlog is not None:
            self.tlog.write(raw)
        taps = self._intercepts.get(msgid) if src is not self.autopilot else None
        if taps and not all([cb(frame) for cb in taps]):  # every tap sees it
            self.stats.for_bridge += 1
            return
        target = frame_target(frame, self._offsets)
        sent = False
        now = 0.0
        for dst in self.endpoints:
            if dst is src or dst.server:
                continue
            if source in dst.seen:  # loop guard: never back to where the source lives
                dst.stats.loop_guard += 1
                continue
            if target is None or dst.accepts(target):
                if dst.filter_out is not None and not dst.filter_out(msgid):
                    dst.stats.filtered_out += 1
                    continue
                if dst.max_out_pps > 0:
                    now = now or self.clock()
                    if not dst.rate_ok(now):
                        continue
                dst.send(raw)
                sent = True
        if sent:
            self.stats.forwarded += 1
        if self._listeners and src is self.autopilot:
            for cb in self._listeners.get(msgid, ()):
                cb(frame)
        mine = target is not None and self._addressed_to_me(target)
        if mine and msgid in _FOR_BRIDGE_IDS:
            self.stats.for_bridge += 1
            self._handle(src, frame, verified)
        elif msgid == _COMMAND_ACK and target is not None and self._ack_for_me(target):
            self.stats.for_bridge += 1
            self._on_ack(frame)
        elif mine and msgid == _FTP and target is not None and target[0] != 0:
            self.stats.for_bridge += 1
            self._ftp_nak(src, frame)
        elif not sent:
            if target is not None and target[0] != 0:
                src.stats.unroutable += 1  # addressed to a system no other endpoint has shown
            else:
                self.stats.no_destination += 1  # a broadcast with nobody (else) to take it

    def _addressed_to_me(self, target: tuple[int, int]) -> bool:
        sysid, compid = target
        return sysid in (0, self.cfg.system_id) and compid in (0, self.cfg.component_id)

    def _ack_for_me(self, target: tuple[int, int]) -> bool:
        """A COMMAND_ACK for the bridge: addressed to its component, or (MAVLink 1, or an
        autopilot that leaves the target empty) to nobody while a command of ours waits."""
        if target == (self.cfg.system_id, self.cfg.component_id):
            return True
        return target == (0, 0) and self._pending is not None

    # -- signing ---------------------------------------------------------------------------

    def _signature_accepted(self, frame: MavFrame) -> bool:
        """MAVLink 2 signing's acceptance rules, counted by reason.

        Signed with our key; newer than the last packet of its (link id, system, component)
        stream; a stream not seen before must be at most one minute behind our timestamp
        (which follows the clock and every accepted packet, and survives a restart through
        the signing state file, with every stream's last timestamp: a packet captured before
        a restart is refused after it).
        """
        if self._key is None or not frame.signed:
            self.stats.refused_unsigned += 1
            return False
        if not signature_ok(frame, self._key):
            self.stats.bad_signature += 1
            return False
        stream = (frame.link_id or 0, frame.sysid, frame.compid)
        ts = frame.signature_timestamp or 0
        last = self._sig_last.get(stream)
        local = max(self._sig_local, mio.signing_timestamp_now())
        if last is not None:
            if ts <= last:
                self.stats.replayed_signature += 1
                return False
        elif ts + SIGNING_NEW_STREAM_WINDOW < local:
            self.stats.old_stream_refused += 1
            return False
        self._sig_last[stream] = ts
        self._sig_local = max(local, ts)
        self._sig_dirty = True
        return True

    def _load_signing_state(self) -> None:
        path = self._sig_state_path
        if path is None or not path.exists():
            return
        try:
            state = json.loads(path.read_text(encoding="utf-8"))
            self._sig_local = int(state.get("timestamp", 0))
            for key, ts in state.get("streams", {}).items():
                link, sysid, compid = (int(x) for x in key.split(","))
                self._sig_last[(link, sysid, compid)] = int(ts)
        except (OSError, ValueError, TypeError, AttributeError) as err:
            log.warning("signing state %s unreadable (%s): starting from the clock", path, err)

    def save_signing_state(self) -> None:
        """Write our signing timestamp and every stream's last one (atomically)."""
        path = self._sig_state_path
        if path is None or not self._sig_dirty:
            return
        state = {"timestamp": max(self._sig_local, mio.signing_timestamp_now()),
                 "streams": {f"{k[0]},{k[1]},{k[2]}": v for k, v in self._sig_last.items()}}
        tmp = path.with_name(path.name + ".tmp")
        try:
            tmp.write_text(json.dumps(state), encoding="utf-8")
            os.chmod(tmp, 0o600)
            os.replace(tmp, path)
        except OSError as err:
            if not self.stats.signing_state_errors:
                log.warning("signing state %s not written (%s); retried", path, err)
            self.stats.signing_state_errors += 1
            return
        self._sig_dirty = False

    # -- what is addressed to the bridge -----------------------------------------------------

    def _on_ack(self, frame: MavFrame) -> None:
        msg = mio.decode_packet(frame.raw)
        with self._lock:
            pending = self._pending
            if msg is None or pending is None or int(msg.command) != pending.command:
                return
            result = int(msg.result)
            if result == mio.MAV_RESULT_IN_PROGRESS:
                pending.due = None  # the autopilot is working on it: wait a full period more
                return
            self._pending = None
        if result == mio.MAV_RESULT_ACCEPTED:
            self.stats.command_accepted += 1
            self.post_statustext(mio.MAV_SEVERITY_INFO, f"FDI: autopilot accepted {pending.what}")
        else:
            self.stats.command_refused += 1
            log.warning("autopilot refused %s (MAV_RESULT %d)", pending.what, result)
            self.post_statustext(mio.MAV_SEVERITY_WARNING,
                                 f"FDI: autopilot REFUSED {pending.what} (result {result})")

    def _retry_command(self, now: float) -> None:
        if self._pending is None:
            return
        with self._lock:
            pending = self._pending
            if pending is None:
                return
            if pending.due is None:
                pending.due = now + self.cfg.command_retry_s
                return
            if now < pending.due:
                return
            if pending.attempts >= self.cfg.command_retries:
                self._pending = None
                self.stats.command_unacked += 1
                give_up = True
            else:
                pending.attempts += 1
                pending.due = now + self.cfg.command_retry_s
                self.stats.command_sent += 1
                give_up = False
        if give_up:
            log.warning("no COMMAND_ACK for %s after %d attempts", pending.what, pending.attempts)
            self.post_statustext(mio.MAV_SEVERITY_WARNING,
                                 f"FDI: no answer from the autopilot to {pending.what}")
            return
        self._emit(pending.encode(), self.autopilot)

    def _ftp_nak(self, src: Endpoint, frame: MavFrame) -> None:
        """MAVLink FTP is not served: NAK at once, so a client (MAVProxy fetching parameters
        by FTP) falls back to PARAM_REQUEST_LIST instead of waiting for its timeout."""
        msg = mio.decode_packet(frame.raw)
        if msg is None:
            return
        req = bytes(msg.payload)
        seq = int.from_bytes(req[0:2], "little")
        session, opcode = req[2], req[3]
        error = _FTP_ERR_FILE_NOT_FOUND if opcode == _FTP_OPEN_RO else _FTP_ERR_FAIL
        reply = struct.pack("<HBBBBBBI", (seq + 1) & 0xFFFF, session, _FTP_NAK, 1, opcode, 0, 0,
                            0) + bytes((error,))
        with self._lock:
            raw = self._own.send_file_transfer_protocol(frame.sysid, frame.compid, reply)
        self.stats.ftp_nak += 1
        self._emit(raw, src)

    def _handle(self, src: Endpoint, frame: MavFrame, verified: bool = False) -> None:
        if src.signing and frame.msgid in _COMMAND_IDS and not verified:
            self.stats.refused_unsigned += 1
            return
        msg = mio.decode_packet(frame.raw)
        if msg is None:
            return
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            names = self.params.names()
            for i, name in enumerate(names):
                self._emit(self._param_value(name, i, len(names)), src)
        elif kind == "PARAM_REQUEST_READ":
            names = self.params.names()
            name = _param_name(msg.param_id)
            idx = int(msg.param_index)
            if idx >= 0:
                name = names[idx] if idx < len(names) else ""
            if name in names:
                self._emit(self._param_value(name, names.index(name), len(names)), src)
        elif kind == "PARAM_SET":
            name = _param_name(msg.param_id)
            names = self.params.names()
            if name not in names:
                self.stats.params_rejected += 1
                return
            if self.params.set(name, float(msg.param_value)):
                self.stats.params_set += 1
            else:
                self.stats.params_rejected += 1
            # Answer with the value now in force (new, or unchanged when refused) to every
            # ground station, once each: a server's peers are endpoints of their own.
            self._emit(self._param_value(name, names.index(name), len(names)), None,
                       gcs_only=True)
        elif kind in ("COMMAND_LONG", "COMMAND_INT"):
            with self._lock:
                raw = self._own.send_command_ack(
                    int(msg.command), mio.MAV_RESULT_UNSUPPORTED,
                    frame.sysid, frame.compid,
                )  # fmt: skip
            self._emit(raw, src)

    def _param_value(self, name: str, index: int, count: int) -> bytes:
        spec = self.params.spec(name)
        kind = mio.MAV_PARAM_TYPE_INT32 if spec.integer else mio.MAV_PARAM_TYPE_REAL32
        with self._lock:
            return self._own.send_param_value(name, self.params.get(name), index, count, kind)

    def _emit(self, raw: bytes, dest: Endpoint | None, *, gcs_only: bool = False) -> None:
        """Send one of the bridge's own packets: to ``dest``, or to every endpoint (every
        ground station's with ``gcs_only``), once each; recorded once in the tlog."""
        self.stats.own_sent += 1
        if self.tlog is not None:
            self.tlog.write(raw)
        if dest is not None:
            dest.send(raw, own=True)
            return
        for ep in self.endpoints:
            if not ep.server and (ep.is_gcs or not gcs_only):  # a server's clients are listed
                ep.send(raw, own=True)

    def _drain_outbox(self) -> None:
        while self._outbox:
            raw, dest = self._outbox.popleft()
            self._emit(raw, dest)

    def tick(self, now: float) -> None:
        """Periodic jobs due at ``now``: heartbeat, NAMED_VALUE_FLOAT, paced STATUSTEXT."""
        cfg = self.cfg
        if now >= self._next_hb:
            with self._lock:
                raw = self._own.send_heartbeat()
            self._emit(raw, None)
            self._next_hb += 1.0 / cfg.heartbeat_hz
            if self._next_hb <= now:  # we were late: skip missed beats, stay on the grid
                periods = int((now - self._next_hb) * cfg.heartbeat_hz) + 1
                self._next_hb += periods / cfg.heartbeat_hz
        if cfg.stats_hz > 0 and now >= self._next_stats:
            with self._lock:
                values = list(self._values.items())
                t_ms = int((now - self._t0) * 1000)
                packets = [self._own.send_named_value_float(n, v, t_ms) for n, v in values]
            for raw in packets:
                self._emit(raw, None)
            self._next_stats += 1.0 / cfg.stats_hz
            if self._next_stats <= now:
                periods = int((now - self._next_stats) * cfg.stats_hz) + 1
                self._next_stats += periods / cfg.stats_hz
        self._retry_command(now)
        if now >= self._next_expiry:
            self._next_expiry = now + 1.0
            self._expire_routes(now)
        if now >= self._next_flush:
            self._next_flush = now + 1.0
            if self.tlog is not None:
                self.tlog.flush()  # at least once a second: a crash loses at most a second
            if self.params.unsaved:
                self.params.retry_save()
        if now >= self._next_slow:
            self._next_slow = now + SIGNING_STATE_EVERY_S
            self.save_signing_state()
        if cfg.report_stats_s > 0 and now >= self._next_report:
            self._next_report = now + cfg.report_stats_s
            log.info("router stats %s", json.dumps(self.summary(), separators=(",", ":")))
        dt = max(0.0, now - self._last_tick)
        self._last_tick = now
        self._text_tokens = min(cfg.statustext_per_s, self._text_tokens + dt * cfg.statustext_per_s)
        while self._texts and self._text_tokens >= 1.0:
            with self._lock:
                severity, text = self._texts.popleft()
                raw = self._own.send_statustext(severity, text)
            self._text_tokens -= 1.0
            self._emit(raw, None)

    def _expire_routes(self, now: float) -> None:
        """Forget what an endpoint has not been heard from for ``route_timeout_s`` (checked
        each second): one packet with another endpoint's ids (an echo) no longer cuts that
        endpoint off by the loop guard, nor draws its targeted messages, for good."""
        timeout = self.cfg.route_timeout_s
        if timeout <= 0:
            return
        old = now - timeout
        for ep in self.endpoints:
            if ep.seen and min(ep.seen.values()) < old:
                stale = [k for k, t in ep.seen.items() if t < old]
                for k in stale:
                    del ep.seen[k]
                self.stats.routes_expired += len(stale)
                ep.seen_sys = {sysid: t for sysid, t in ep.seen_sys.items() if t >= old}

    def run(self, stop: threading.Event | None = None, poll_s: float = 0.05) -> None:
        """Poll until ``stop`` is set (or :meth:`stop` is called)."""
        stop = stop or self._stop
        while not stop.is_set():
            self.poll(poll_s)
        if self.tlog is not None:
            self.tlog.flush()

    def start(self) -> threading.Thread:
        """Run the loop in a daemon thread; :meth:`close` stops it."""
        self._thread = threading.Thread(target=self.run, name="mavlink-router", daemon=True)
        self._thread.start()
        return self._thread

    def close(self) -> None:
        self._stop.set()
        if hasattr(self, "_wake_w"):
            self._wake()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        for ep in self.endpoints:
            ep.link.close()
        if hasattr(self, "_sel"):
            self._sel.close()
            self._wake_r.close()
            self._wake_w.close()
        if self.tlog is not None:
            self.tlog.close()
        if hasattr(self, "_sig_dirty"):
            self.save_signing_state()

    def summary(self) -> dict[str, Any]:
        """Counters of the router and of each endpoint (for logs and tests)."""
        out: dict[str, Any] = dict(self.stats.__dict__)
        out["params_rejected"] += self.params.rejected - self.stats.params_rejected
        out["param_write_errors"] = self.params.write_errors
        out["params_unsaved"] = self.params.unsaved
        if self.tlog is not None:
            out.update(self.tlog.counters())
        for ep in self.endpoints:
            extra: dict[str, Any] = {"queued": len(ep.queue) + len(ep.own_queue),
                                     "link_errors": ep.link.errors}
            dropped = getattr(ep.link, "dropped", None)
            if dropped is not None:  # datagrams a full send buffer lost (UDP)
                extra["send_dropped"] = dropped
            kernel_drops = getattr(ep.link, "kernel_drops", None)
            if kernel_drops is not None:  # what the kernel dropped before the router read it
                extra["rx_kernel_drops"] = kernel_drops() or 0
            counts = dict(ep.stats.__dict__)
            if ep.server:  # the server's line adds up its clients, present and gone
                extra.update(clients=ep.clients, clients_gone=ep.clients_gone)
                for child in [*ep.children, None]:
                    st = child.stats if child is not None else ep.gone_stats
                    for name, value in st.__dict__.items():
                        counts[name] += value
                extra["queued"] += sum(len(c.queue) + len(c.own_queue) for c in ep.children)
                extra["send_dropped"] = extra.get("send_dropped", 0) + sum(
                    getattr(c.link, "dropped", 0) for c in ep.children)
            foreign = getattr(ep.link, "foreign", None)
            if foreign is not None:
                extra["foreign_dropped"] = foreign
            out[ep.name] = dict(counts, **extra)
        return out


def _param_name(raw: Any) -> str:
    if isinstance(raw, bytes | bytearray):
        raw = raw.split(b"\0", 1)[0].decode("ascii", errors="replace")
    return str(raw).split("\0", 1)[0]


def open_router(cfg: MavlinkConfig) -> Router:
    """The router of a ``[mavlink]`` table with its parameter store (``param_file``): what a
    command hands the :class:`~firmware_host.runtime.runner.Runner` as ``open_router``."""
    return Router(cfg, params=ParamStore(cfg.param_file or None))
