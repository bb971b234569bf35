"""Non-blocking byte links for the MAVLink router: UDP server/client, TCP server/client, serial.

A link moves bytes only; framing is :mod:`drivers.mavlink.framer`'s job. Links are opened from
a URL in the mavutil / MAVProxy spelling:

=======================  =========================================================
``udpin:HOST:PORT``      UDP server: bind and answer every peer that has sent to it
``udpin:PORT``           the same on **127.0.0.1** (a server is never public by default)
``udpout:HOST:PORT``     UDP client: send to HOST:PORT, accept its answers
``tcpin:HOST:PORT``      TCP server (``tcpin:PORT`` binds 127.0.0.1), any number of clients
``tcp:HOST:PORT``        TCP client
anything else            a pyserial URL or device path, opened with ``baud``
=======================  =========================================================

``read(max_chunks)`` yields ``(chunk, stream_key, boundary)`` one at a time as it reads them,
so the router forwards a datagram before it reads the next one: ``stream_key`` names the byte
stream the chunk belongs to (one framer per stream: a UDP peer, a TCP client, the serial line)
and ``boundary`` is True when the chunk ended a datagram. ``write(data)`` returns False when the
link cannot take the bytes now (kernel buffer full): the router keeps them in its bounded
queue and waits for :meth:`Link.write_filenos` to become writable. Stream links (TCP, serial)
keep a short backlog of their own (a partial write); :meth:`Link.flush` pushes it on.
An endpoint that cannot be opened at start (its port held by another process, an address that
is not an address or not on this machine, a port out of range, a refused first TCP connection)
raises :class:`~fdi.errors.EndpointError`: one line naming the URL and, where the kernel tells,
the process that holds the port (:func:`port_holder`, as ``ss -p`` finds it). A UDP server
binds without ``SO_REUSEADDR``: with it, Linux lets two programs that both set it (mavutil's
``udpin`` does) share one port, each getting part of the datagrams, silently. At run time a
failing peer is dropped and counted, never raised into the forwarding loop.
"""

from __future__ import annotations

import errno
import logging
import os
import socket
import time
from abc import ABC, abstractmethod
from collections.abc import Hashable, Iterator

from drivers import devices
from drivers.resilient import ResilientPort
from drivers.transport import SerialSettings, open_port_nonblocking
from fdi.errors import EndpointError

Chunk = tuple[bytes, Hashable, bool]
log = logging.getLogger("fdi_bridge.mavlink")

DEFAULT_SERVER_HOST = "127.0.0.1"
MAX_UDP_PEERS = 16
UDP_PEER_TIMEOUT_S = 0.0
"""Default for a UDP server's ``peer_timeout_s``: 0 = a peer is kept until 16 others displace it
(a listen-only ground station never goes dark); > 0 stops sending to a silent peer."""
# Receive buffer asked for on UDP sockets (the kernel caps it at net.core.rmem_max): ~1 s of a
# 1 000 packet/s link, so a burst that arrives while the loop is descheduled is not dropped by
# the kernel before the router's own (counted) queues see it.
UDP_RCVBUF_BYTES = 1 << 20
_WOULD_BLOCK = (errno.EAGAIN, errno.EWOULDBLOCK, errno.ENOBUFS)


# The mavutil / MAVProxy network spellings; anything else is a serial device or pyserial URL.
NETWORK_SCHEMES = ("udpin", "udpout", "udp", "udpbcast", "tcp", "tcpin")


def is_network_url(url: str) -> bool:
    """True for ``udpout:HOST:PORT`` and the other network spellings, False for a device."""
    scheme, sep, _rest = url.partition(":")
    return bool(sep) and scheme in NETWORK_SCHEMES


def _split_hostport(rest: str, url: str, default_host: str | None) -> tuple[str, int]:
    host, sep, port = rest.rpartition(":")
    if not sep:
        host, port = "", rest
    if not host:
        if default_host is None:
            raise EndpointError(f"{url}: expected HOST:PORT")
        host = default_host
    try:
        number = int(port)
    except ValueError as err:
        raise EndpointError(f"{url}: the port must be a number 0-65535, found {port!r}") from err
    if not 0 <= number <= 65535:
        raise EndpointError(f"{url}: the port must be 0-65535, found {number}")
    return host, number


def _address(host: str, url: str) -> str:
    """``host`` as an IPv4 address (a name is resolved); EndpointError naming ``url``."""
    if host.replace(".", "").isdigit():  # digits and dots: checked here, never sent to DNS
        parts = host.split(".")
        if len(parts) == 4 and all(p and int(p) <= 255 for p in parts):
            return ".".join(str(int(p)) for p in parts)
        raise EndpointError(f"{url}: {host!r} is not an IPv4 address (four numbers 0-255)")
    try:
        return socket.gethostbyname(host)
    except (OSError, UnicodeError) as err:
        raise EndpointError(f"{url}: {host!r} is neither an IPv4 address nor a known host name "
                            f"({_strerror(err)})") from err


def _strerror(err: BaseException) -> str:
    return str(getattr(err, "strerror", None) or err)


def open_error(url: str, proto: str, port: int, err: OSError, what: str) -> EndpointError:
    """The start-up error for ``err`` raised while binding/connecting ``url``: a busy port names
    its holder where it can (:func:`port_holder`)."""
    if err.errno == errno.EADDRINUSE:
        holder = port_holder(proto, port)
        by = f" by {holder}" if holder else " by another program"
        return EndpointError(f"{url}: {proto.upper()} port {port} is already in use{by}; stop "
                             f"it or choose another port")
    if err.errno == errno.EADDRNOTAVAIL:
        return EndpointError(f"{url}: the address is not one of this machine's (ip -br addr "
                             f"lists them)")
    if err.errno == errno.EACCES and port < 1024:
        return EndpointError(f"{url}: port {port} needs root (ports below 1024); use 1024 or above")
    return EndpointError(f"{url}: could not {what}: {_strerror(err)}")


def udp_socket_drops(sock: socket.socket) -> int | None:
    """The kernel's drop count of UDP socket ``sock`` (``/proc/net/udp`` ``drops``), or None."""
    try:
        inode = str(os.fstat(sock.fileno()).st_ino)
    except (OSError, ValueError):
        return None
    for cols in _proc_net_rows("udp"):
        if len(cols) >= 13 and cols[9] == inode:
            try:
                return int(cols[12])
            except ValueError:
                return None
    return None


def _proc_net_rows(proto: str) -> Iterator[list[str]]:
    """The socket rows of ``/proc/net/<proto>`` and ``/proc/net/<proto>6``, split into
    columns (Linux; none where a table cannot be read)."""
    for table in (f"/proc/net/{proto}", f"/proc/net/{proto}6"):
        try:
            with open(table, encoding="ascii") as f:
                lines = f.read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            yield line.split()


def port_holder(proto: str, port: int) -> str:
    """Best effort, Linux only: who holds local ``proto`` (``"udp"``/``"tcp"``) ``port``, as
    ``ss -p`` finds it: the socket's inode in ``/proc/net/<proto>[6]``, then the process whose
    ``/proc/<pid>/fd`` links to it. ``"pid 1234 (mavproxy.py --master ...)"``; for another
    user's process, whose descriptors are not readable, ``"a process of uid 1000"``; ``""``
    when nothing is found."""
    inodes: dict[str, int] = {}
    for cols in _proc_net_rows(proto):
        if len(cols) < 10 or ":" not in cols[1]:
            continue
        try:
            local_port = int(cols[1].rsplit(":", 1)[1], 16)
        except ValueError:
            continue
        if local_port != port or (proto == "tcp" and cols[3] != "0A"):  # 0A: LISTEN
            continue
        try:
            inodes[cols[9]] = int(cols[7])
        except ValueError:
            continue
    inodes.pop("0", None)
    if not inodes:
        return ""
    for inode in inodes:
        pids = devices.openers(f"socket:[{inode}]")
        if pids:
            return str(devices.Holder(pids[0], devices.command(pids[0])))
    uid = next(iter(inodes.values()))
    return f"a process of uid {uid}"


class Link(ABC):
    """One endpoint's transport (see the module docstring)."""

    url: str
    errors: int = 0

    @abstractmethod
    def filenos(self) -> list[int]:
        """File descriptors to wait on (may change as TCP clients come and go)."""

    @abstractmethod
    def read(self, max_chunks: int) -> Iterator[Chunk]:
        """Yield at most ``max_chunks`` chunks that can be read now, without blocking."""

    @abstractmethod
    def write(self, data: bytes) -> bool: ...

    def backlog(self) -> bool:
        """True when the link holds bytes of its own that a :meth:`flush` should push on."""
        return False

    def write_filenos(self) -> list[int]:
        """Descriptors whose writability unblocks the link's backlog (default: all of them)."""
        return self.filenos()

    def flush(self) -> None:
        """Write what the link holds back (a partial TCP or serial write); never blocks."""
        return None  # datagram links hold nothing back

    @abstractmethod
    def close(self) -> None: ...

    @property
    def local_address(self) -> tuple[str, int] | None:
        return None

    def has_peer(self) -> bool:
        """True when a write can reach someone (a UDP server has heard from a peer)."""
        return True


class _UdpLink(Link):
    """A link on one UDP socket (``sock``)."""

    sock: socket.socket

    @property
    def local_address(self) -> tuple[str, int]:
        host, port = self.sock.getsockname()[:2]
        return str(host), int(port)

    def filenos(self) -> list[int]:
        return [self.sock.fileno()]

    def kernel_drops(self) -> int | None:
        """Datagrams the kernel dropped on this socket because its receive buffer was full
        (the router did not read them in time): the ``drops`` column of ``/proc/net/udp`` for
        the socket's inode (Linux; None where it cannot be read). Read when asked, not per
        packet."""
        return udp_socket_drops(self.sock)


class UdpServerLink(_UdpLink):
    def __init__(self, url: str, host: str, port: int,
                 peer_timeout_s: float = UDP_PEER_TIMEOUT_S) -> None:
        self.url = url
        self._clock = time.monotonic
        self.peer_timeout_s = peer_timeout_s
        address = _address(host, url)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            # No SO_REUSEADDR (see the module docstring): a port in use is an error, not a share.
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RCVBUF_BYTES)
            self.sock.bind((address, port))
            self.sock.setblocking(False)
        except OSError as err:
            self.sock.close()
            raise open_error(url, "udp", port, err, "bind") from err
        self.peers: dict[tuple[str, int], float] = {}
        self.dropped = 0  # datagrams a peer lost because the socket's send buffer was full

    def read(self, max_chunks: int) -> Iterator[Chunk]:
        now = self._clock()
        recvfrom = self.sock.recvfrom
        peers = self.peers
        for _ in range(max_chunks):
            try:
                data, addr = recvfrom(65535)
            except BlockingIOError:
                return
            except OSError:
                self.errors += 1  # e.g. ICMP port unreachable reported on a later call
                return
            if addr not in peers and len(peers) >= MAX_UDP_PEERS:
                oldest = min(peers, key=peers.__getitem__)
                del peers[oldest]
            peers[addr] = now
            yield data, addr, True

    def write(self, data: bytes) -> bool:
        peers = self.peers
        timeout = self.peer_timeout_s
        if len(peers) == 1:  # the usual case: one ground station
            addr = next(iter(peers))
            if timeout > 0 and self._clock() - peers[addr] > timeout:
                del peers[addr]
                return True
            return self._sendto(data, addr)
        now = self._clock()
        for addr, seen in list(peers.items()):
            if timeout > 0 and now - seen > timeout:
                del peers[addr]
            elif not self._sendto(data, addr):
                # One peer's buffer is full: that peer loses this datagram (as on the air);
                # returning False would send it again to the peers that already have it.
                self.dropped += 1
        return True

    def _sendto(self, data: bytes, addr: tuple[str, int]) -> bool:
        try:
            self.sock.sendto(data, addr)
        except OSError as err:
            if err.errno in _WOULD_BLOCK:
                return False
            self.errors += 1
        return True

    def has_peer(self) -> bool:
        return bool(self.peers)

    def close(self) -> None:
        self.sock.close()


class UdpPeerLink(Link):
    """One peer of a UDP server link, as a link of its own: writes go to that address only,
    through the server's socket (the server reads for every peer). A full send buffer loses
    the datagram for this peer (counted in ``dropped``), as on the air."""

    passive = True  # no descriptor of its own: its server's socket is waited on

    def __init__(self, server: UdpServerLink, addr: tuple[str, int]) -> None:
        self.url = f"{server.url}#{addr[0]}:{addr[1]}"
        self.server = server
        self.addr = addr
        self.dropped = 0

    def filenos(self) -> list[int]:
        return []

    def write_filenos(self) -> list[int]:
        return []

    def read(self, max_chunks: int) -> Iterator[Chunk]:
        return iter(())

    def write(self, data: bytes) -> bool:
        if not self.server._sendto(data, self.addr):
            self.dropped += 1
        return True

    def has_peer(self) -> bool:
        srv = self.server
        seen = srv.peers.get(self.addr)
        if seen is None:
            return False
        if srv.peer_timeout_s > 0 and srv._clock() - seen > srv.peer_timeout_s:
            del srv.peers[self.addr]
            return False
        return True

    @property
    def errors(self) -> int:  # type: ignore[override]
        return 0

    def close(self) -> None:
        return None  # the server's socket is the server's


class UdpClientLink(_UdpLink):
    """``udpout:HOST:PORT``: sends to HOST:PORT and accepts datagrams from that address only
    (``accept_any=True``: from any sender, as mavutil does); others are dropped and counted in
    ``foreign``, so another local program cannot inject packets through the link."""

    def __init__(self, url: str, host: str, port: int, accept_any: bool = False) -> None:
        self.url = url
        self.accept_any = accept_any
        self.foreign = 0
        if port == 0:
            raise EndpointError(f"{url}: a udpout: link needs the port to send to (1-65535)")
        self.target = (_address(host, url), port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RCVBUF_BYTES)
            self.sock.setblocking(False)
            self.sock.bind(("0.0.0.0" if host not in ("127.0.0.1", "localhost") else host, 0))
        except OSError as err:
            self.sock.close()
            raise open_error(url, "udp", 0, err, "open a UDP socket") from err

    def read(self, max_chunks: int) -> Iterator[Chunk]:
        recvfrom = self.sock.recvfrom
        for _ in range(max_chunks):
            try:
                data, addr = recvfrom(65535)
            except BlockingIOError:
                return
            except OSError:
                self.errors += 1  # ICMP port unreachable while nobody listens yet
                return
            if addr != self.target and not self.accept_any:
                self.foreign += 1
                continue
            yield data, addr, True

    def write(self, data: bytes) -> bool:
        try:
            self.sock.sendto(data, self.target)
        except OSError as err:
            if err.errno in _WOULD_BLOCK:
                return False
            self.errors += 1  # nobody listening yet: the datagram is lost, as on the air
        return True

    def close(self) -> None:
        self.sock.close()


class _TcpConn:
    def __init__(self, sock: socket.socket, key: Hashable) -> None:
        self.sock = sock
        self.key = key
        self.out = bytearray()


MAX_TCP_BACKLOG = 64 * 1024
TCP_SNDBUF_BYTES = 64 * 1024
"""The kernel send buffer asked for on each TCP connection (Linux doubles it and stops
autotuning it). Left to autotune, a client that stops reading lets the kernel hold up to
tcp_wmem's maximum (4 MB by default, more on tuned kernels): at telemetry rates a minute of
stale packets, and a drop point that depends on the machine. Bounded, a slow client holds at
most about twice this in the kernel, plus ``MAX_TCP_BACKLOG``, plus its endpoint's queue; past
that its oldest packets are dropped and counted (``dropped_queue_full``), so it gets fresh
telemetry when it reads again, and the other clients are unaffected."""


def _tcp_options(sock: socket.socket) -> None:
    sock.setblocking(False)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, TCP_SNDBUF_BYTES)


class _TcpBase(Link):
    conns: list[_TcpConn]

    def filenos(self) -> list[int]:
        return [c.sock.fileno() for c in self.conns]

    def _read_conns(self, max_chunks: int) -> Iterator[Chunk]:
        for c in list(self.conns):
            for _ in range(max_chunks):
                try:
                    data = c.sock.recv(65536)
                except BlockingIOError:
                    break
                except OSError:
                    data = b""
                if not data:
                    self._lost(c)
                    break
                yield data, c.key, False

    def _lost(self, c: _TcpConn) -> None:
        self.errors += 1
        c.sock.close()
        if c in self.conns:
            self.conns.remove(c)

    def write(self, data: bytes) -> bool:
        ok = True
        for c in list(self.conns):
            if len(c.out) > MAX_TCP_BACKLOG:
                self._send(c)
                if len(c.out) > MAX_TCP_BACKLOG:
                    ok = False  # this client is slow: the router keeps the packet queued
                    continue
            if c.out:
                c.out += data
                self._send(c)
                continue
            try:
                sent = c.sock.send(data)
            except BlockingIOError:
                sent = 0
            except OSError:
                self._lost(c)
                continue
            if sent < len(data):
                c.out += data[sent:]
        return ok

    def _send(self, c: _TcpConn) -> None:
        try:
            sent = c.sock.send(c.out)
            del c.out[:sent]
        except BlockingIOError:
            pass
        except OSError:
            self._lost(c)

    def backlog(self) -> bool:
        return any(c.out for c in self.conns)

    def flush(self) -> None:
        for c in list(self.conns):
            if c.out:
                self._send(c)

    def write_filenos(self) -> list[int]:
        return [c.sock.fileno() for c in self.conns if c.out]

    def close(self) -> None:
        for c in self.conns:
            c.sock.close()
        self.conns = []


class TcpServerLink(_TcpBase):
    def __init__(self, url: str, host: str, port: int) -> None:
        self.url = url
        self.conns = []
        self.children: list[TcpClientConnLink] = []
        self._n = 0
        address = _address(host, url)
        self.listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            # SO_REUSEADDR on a TCP listener only skips TIME_WAIT after a restart: Linux still
            # refuses a second listener on the port (EADDRINUSE).
            self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.listener.bind((address, port))
            self.listener.listen(8)
            self.listener.setblocking(False)
        except OSError as err:
            self.listener.close()
            raise open_error(url, "tcp", port, err, "listen") from err

    @property
    def local_address(self) -> tuple[str, int]:
        host, port = self.listener.getsockname()[:2]
        return str(host), int(port)

    def filenos(self) -> list[int]:
        return [self.listener.fileno(), *super().filenos()]

    def read(self, max_chunks: int) -> Iterator[Chunk]:
        for link in self.accept_links():
            self.conns.extend(link.conns)
        return self._read_conns(max_chunks)

    def accept_links(self) -> list[TcpClientConnLink]:
        """Accept every waiting client, each as a link of its own (the router makes each one
        an endpoint: its own routes, queue and counters)."""
        out: list[TcpClientConnLink] = []
        while True:
            try:
                sock, addr = self.listener.accept()
            except (BlockingIOError, OSError):
                break
            _tcp_options(sock)
            self._n += 1
            out.append(TcpClientConnLink(f"{self.url}#{self._n}", sock, ("tcp", self._n, addr)))
        self.children = [c for c in self.children if c.has_peer()] + out
        return out

    def listener_filenos(self) -> list[int]:
        return [self.listener.fileno()]

    def has_peer(self) -> bool:
        return bool(self.conns) or any(c.has_peer() for c in self.children)

    def close(self) -> None:
        super().close()
        for c in self.children:
            c.close()
        self.listener.close()


class TcpClientConnLink(_TcpBase):
    """One accepted client of a TCP server link: its socket, its own write backlog."""

    def __init__(self, url: str, sock: socket.socket, key: Hashable) -> None:
        self.url = url
        self.conns = [_TcpConn(sock, key)]

    def read(self, max_chunks: int) -> Iterator[Chunk]:
        return self._read_conns(max_chunks)

    def has_peer(self) -> bool:
        return bool(self.conns)


class TcpClientLink(_TcpBase):
    """A TCP client (``tcp:HOST:PORT``, as SITL listens on 5760) that connects again when lost.

    The first connection is made at start (a refused one is a start-up error). When the server
    closes or resets it (SITL restarted, the companion's server gone), the loss is counted in
    ``errors`` and logged once, and the link reconnects by itself, as mavlink-router's TCP
    endpoints do: an attempt after 0.1 s, then 0.2, 0.4 ... capped at ``retry_max_s``; each
    attempt waits at most ``retry_timeout_s`` for the connection (the router's loop waits with
    it). While it is down the router counts its packets as ``no_peer``.
    """

    def __init__(self, url: str, host: str, port: int, connect_timeout_s: float = 5.0,
                 retry_max_s: float = 5.0, retry_timeout_s: float = 0.1) -> None:
        self.url = url
        self._addr = (host, port)
        self.retry_max_s = retry_max_s
        self.retry_timeout_s = retry_timeout_s
        self.reconnects = 0
        self._backoff = 0.1
        self._next_try = 0.0
        if port == 0:
            raise EndpointError(f"{url}: a tcp: link needs the port to connect to (1-65535)")
        self._addr = (_address(host, url), port)
        try:
            sock = self._connect(connect_timeout_s)
        except OSError as err:
            raise EndpointError(f"{url}: could not connect: {_strerror(err)} (is the server "
                                f"running?)") from err
        self.conns = [_TcpConn(sock, ("tcp", host, port))]

    def _connect(self, timeout_s: float) -> socket.socket:
        sock = socket.create_connection(self._addr, timeout=timeout_s)
        _tcp_options(sock)
        return sock

    def _lost(self, c: _TcpConn) -> None:
        super()._lost(c)
        log.warning("%s: connection lost; reconnecting with backoff up to %.1f s", self.url,
                    self.retry_max_s)
        self._backoff = 0.1
        self._next_try = time.monotonic() + self._backoff

    def _retry(self) -> None:
        now = time.monotonic()
        if now < self._next_try:
            return
        try:
            sock = self._connect(self.retry_timeout_s)
        except OSError as err:
            log.debug("%s: still down: %s", self.url, err)
            self._backoff = min(2.0 * self._backoff, self.retry_max_s)
            self._next_try = now + self._backoff
            return
        self.reconnects += 1
        log.warning("%s: connected again", self.url)
        # A new stream key: the new connection gets a framer of its own, not the old one's
        # half-received packet.
        self.conns = [_TcpConn(sock, ("tcp", *self._addr, self.reconnects))]

    def read(self, max_chunks: int) -> Iterator[Chunk]:
        if not self.conns:
            self._retry()
        return self._read_conns(max_chunks)

    def has_peer(self) -> bool:
        return bool(self.conns)


class SerialLink(Link):
    """A pyserial URL (``/dev/ttyACM0``, a pty, ``loop://``) read and written without blocking.

    The port is a :class:`~drivers.resilient.ResilientPort`: when the device goes away (USB
    unplugged, the autopilot rebooting and its USB port vanishing with it) the loss is logged
    once and counted, the router keeps forwarding between the other links, and the same URL is
    reopened with backoff (capped at ``backoff_max_s``); while it is down its descriptor leaves
    the router's select and the router polls it. A device absent at start is not fatal either.
    """

    def __init__(self, url: str, baud: int, backoff_max_s: float = 5.0) -> None:
        self.url = url
        self.port = ResilientPort(SerialSettings(url=url, baudrate=baud, timeout_s=0.0),
                                  name=f"mavlink {url}", backoff_max_s=backoff_max_s,
                                  opener=open_port_nonblocking)
        self._key = ("serial", url)
        self._out = bytearray()

    def filenos(self) -> list[int]:
        try:
            return [int(self.port.fileno())]
        except (AttributeError, OSError, ValueError, NotImplementedError):
            return []  # loop:// and friends, and a port that is down: the router polls them

    def read(self, max_chunks: int) -> Iterator[Chunk]:
        if not self.port.service():  # down: a reopen is tried when its backoff is due
            return iter(())
        waiting = self.port.in_waiting
        data = self.port.read(waiting or 1) if waiting or self.filenos() else b""
        return iter([(data, self._key, False)] if data else ())

    def write(self, data: bytes) -> bool:
        if not self.port.up:
            self.port.write(data)  # counted as dropped (or sent, if the reopen is due now)
            return True
        if len(self._out) > MAX_TCP_BACKLOG:
            self._flush()
            return False
        self._out += data
        self._flush()
        return True

    def backlog(self) -> bool:
        return bool(self._out)

    def flush(self) -> None:
        self._flush()

    def write_filenos(self) -> list[int]:
        return self.filenos() if self._out else []

    def _flush(self) -> None:
        if not self._out:
            return
        losses = self.port.losses
        n = self.port.write(bytes(self._out))
        if self.port.losses != losses:  # lost on this write (counted as dropped): start afresh
            self._out.clear()
            return
        del self._out[: n or 0]

    @property
    def errors(self) -> int:
        """Losses of the device and failed reopen attempts."""
        return self.port.losses + self.port.open_failures

    @errors.setter
    def errors(self, value: int) -> None:
        raise AttributeError("SerialLink.errors counts the port's losses")

    def close(self) -> None:
        self.port.close()


def open_link(url: str, baud: int = 115200, backoff_max_s: float = 5.0, *,
              peer_timeout_s: float = UDP_PEER_TIMEOUT_S, accept_any: bool = False) -> Link:
    """Open a link from its URL (see the module docstring); ``backoff_max_s``: the longest wait
    between reconnection attempts of a serial or TCP client link; ``peer_timeout_s``: a UDP
    server's silent-peer timeout (0 = never); ``accept_any``: a UDP client takes datagrams
    from any sender, not only from the address it sends to."""
    scheme, sep, rest = url.partition(":")
    if sep and scheme == "udpin":
        host, port = _split_hostport(rest, url, DEFAULT_SERVER_HOST)
        return UdpServerLink(url, host, port, peer_timeout_s)
    if sep and scheme == "udpout":
        host, port = _split_hostport(rest, url, None)
        return UdpClientLink(url, host, port, accept_any)
    if sep and scheme == "tcpin":
        host, port = _split_hostport(rest, url, DEFAULT_SERVER_HOST)
        return TcpServerLink(url, host, port)
    if sep and scheme == "tcp":
        host, port = _split_hostport(rest, url, None)
        return TcpClientLink(url, host, port, retry_max_s=backoff_max_s)
    return SerialLink(url, baud, backoff_max_s)
