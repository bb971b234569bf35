"""Non-blocking byte links for the MAVLink router: UDP server/client, TCP server/client, serial.

A link moves bytes only; framing is :mod:`drivers.mavlink_framer`'s job. Links are opened from
a URL in the mavutil / MAVProxy spelling:

=======================  =========================================================
``udpin:HOST:PORT``      UDP server: bind and answer every peer that has sent to it
``udpin:PORT``           the same on **127.0.0.1** (a server is never public by default)
``udpout:HOST:PORT``     UDP client: send to HOST:PORT, accept its answers
``tcpin:HOST:PORT``      TCP server (``tcpin:PORT`` binds 127.0.0.1), any number of clients
``tcp:HOST:PORT``        TCP client
anything else            a pyserial URL or device path, opened with ``baud``
=======================  =========================================================

``read()`` returns ``[(chunk, stream_key, boundary)]``: ``stream_key`` names the byte stream the
chunk belongs to (one framer per stream: a UDP peer, a TCP client, the serial line) and
``boundary`` is True when the chunk ended a datagram. ``write(data)`` returns False when the
link cannot take the bytes now (kernel buffer full): the router keeps them in its bounded
queue. OS errors are translated into :class:`~fdi.errors.PortError` at open time; at run time a
failing peer is dropped and counted, never raised into the forwarding loop.
"""

from __future__ import annotations

import errno
import socket
import time
from abc import ABC, abstractmethod
from collections.abc import Hashable

from drivers.transport import SerialSettings, open_port
from fdi.errors import PortError

Chunk = tuple[bytes, Hashable, bool]

DEFAULT_SERVER_HOST = "127.0.0.1"
MAX_UDP_PEERS = 16
UDP_PEER_TIMEOUT_S = 30.0
_WOULD_BLOCK = (errno.EAGAIN, errno.EWOULDBLOCK, errno.ENOBUFS)


def _split_hostport(rest: str, url: str, default_host: str | None) -> tuple[str, int]:
    host, sep, port = rest.rpartition(":")
    if not sep:
        host, port = "", rest
    if not host:
        if default_host is None:
            raise PortError(f"{url!r}: expected HOST:PORT")
        host = default_host
    try:
        return host, int(port)
    except ValueError as err:
        raise PortError(f"{url!r}: bad port {port!r}") from err


class Link(ABC):
    """One endpoint's transport (see the module docstring)."""

    url: str
    errors: int = 0

    @abstractmethod
    def filenos(self) -> list[int]:
        """File descriptors to wait on (may change as TCP clients come and go)."""

    @abstractmethod
    def read(self, max_chunks: int) -> list[Chunk]: ...

    @abstractmethod
    def write(self, data: bytes) -> bool: ...

    @abstractmethod
    def close(self) -> None: ...

    @property
    def local_address(self) -> tuple[str, int] | None:
        return None

    def has_peer(self) -> bool:
        """True when a write can reach someone (a UDP server has heard from a peer)."""
        return True


class UdpServerLink(Link):
    def __init__(self, url: str, host: str, port: int) -> None:
        self.url = url
        self._clock = time.monotonic
        try:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.sock.bind((host, port))
            self.sock.setblocking(False)
        except OSError as err:
            raise PortError(f"could not bind {url!r}: {err}") from err
        self.peers: dict[tuple[str, int], float] = {}

    @property
    def local_address(self) -> tuple[str, int]:
        host, port = self.sock.getsockname()[:2]
        return str(host), int(port)

    def filenos(self) -> list[int]:
        return [self.sock.fileno()]

    def read(self, max_chunks: int) -> list[Chunk]:
        out: list[Chunk] = []
        now = self._clock()
        for _ in range(max_chunks):
            try:
                data, addr = self.sock.recvfrom(65535)
            except BlockingIOError:
                break
            except OSError:
                self.errors += 1  # e.g. ICMP port unreachable reported on a later call
                break
            if addr not in self.peers and len(self.peers) >= MAX_UDP_PEERS:
                oldest = min(self.peers, key=self.peers.__getitem__)
                del self.peers[oldest]
            self.peers[addr] = now
            out.append((data, addr, True))
        return out

    def write(self, data: bytes) -> bool:
        now = self._clock()
        for addr, seen in list(self.peers.items()):
            if now - seen > UDP_PEER_TIMEOUT_S:
                del self.peers[addr]
                continue
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


class UdpClientLink(Link):
    def __init__(self, url: str, host: str, port: int) -> None:
        self.url = url
        try:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.setblocking(False)
            self.target = (socket.gethostbyname(host), port)
            self.sock.bind(("0.0.0.0" if host not in ("127.0.0.1", "localhost") else host, 0))
        except OSError as err:
            raise PortError(f"could not open {url!r}: {err}") from err

    @property
    def local_address(self) -> tuple[str, int]:
        host, port = self.sock.getsockname()[:2]
        return str(host), int(port)

    def filenos(self) -> list[int]:
        return [self.sock.fileno()]

    def read(self, max_chunks: int) -> list[Chunk]:
        out: list[Chunk] = []
        for _ in range(max_chunks):
            try:
                data, addr = self.sock.recvfrom(65535)
            except BlockingIOError:
                break
            except OSError:
                self.errors += 1  # ICMP port unreachable while nobody listens yet
                break
            out.append((data, addr, True))
        return out

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


class _TcpBase(Link):
    conns: list[_TcpConn]

    def filenos(self) -> list[int]:
        return [c.sock.fileno() for c in self.conns]

    def _read_conns(self, max_chunks: int) -> list[Chunk]:
        out: list[Chunk] = []
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
                out.append((data, c.key, False))
        return out

    def _lost(self, c: _TcpConn) -> None:
        self.errors += 1
        c.sock.close()
        if c in self.conns:
            self.conns.remove(c)

    def write(self, data: bytes) -> bool:
        ok = True
        for c in list(self.conns):
            if len(c.out) > MAX_TCP_BACKLOG:
                ok = False
                continue
            c.out += data
            try:
                sent = c.sock.send(c.out)
                del c.out[:sent]
            except BlockingIOError:
                pass
            except OSError:
                self._lost(c)
        return ok

    def close(self) -> None:
        for c in self.conns:
            c.sock.close()
        self.conns = []


class TcpServerLink(_TcpBase):
    def __init__(self, url: str, host: str, port: int) -> None:
        self.url = url
        self.conns = []
        self._n = 0
        try:
            self.listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.listener.bind((host, port))
            self.listener.listen(8)
            self.listener.setblocking(False)
        except OSError as err:
            raise PortError(f"could not listen on {url!r}: {err}") from err

    @property
    def local_address(self) -> tuple[str, int]:
        host, port = self.listener.getsockname()[:2]
        return str(host), int(port)

    def filenos(self) -> list[int]:
        return [self.listener.fileno(), *super().filenos()]

    def read(self, max_chunks: int) -> list[Chunk]:
        while True:
            try:
                sock, addr = self.listener.accept()
            except (BlockingIOError, OSError):
                break
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._n += 1
            self.conns.append(_TcpConn(sock, ("tcp", self._n, addr)))
        return self._read_conns(max_chunks)

    def has_peer(self) -> bool:
        return bool(self.conns)

    def close(self) -> None:
        super().close()
        self.listener.close()


class TcpClientLink(_TcpBase):
    def __init__(self, url: str, host: str, port: int, connect_timeout_s: float = 5.0) -> None:
        self.url = url
        try:
            sock = socket.create_connection((host, port), timeout=connect_timeout_s)
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except OSError as err:
            raise PortError(f"could not connect to {url!r}: {err}") from err
        self.conns = [_TcpConn(sock, ("tcp", host, port))]

    def read(self, max_chunks: int) -> list[Chunk]:
        return self._read_conns(max_chunks)


class SerialLink(Link):
    """A pyserial URL (``/dev/ttyACM0``, a pty, ``loop://``) read and written without blocking."""

    def __init__(self, url: str, baud: int) -> None:
        self.url = url
        self.port = open_port(SerialSettings(url=url, baudrate=baud, timeout_s=0.0))
        self.port.write_timeout = 0
        self._key = ("serial", url)
        self._out = bytearray()

    def filenos(self) -> list[int]:
        try:
            return [int(self.port.fileno())]
        except (AttributeError, OSError, ValueError, NotImplementedError):
            return []  # loop:// and friends: the router polls them

    def read(self, max_chunks: int) -> list[Chunk]:
        try:
            waiting = int(getattr(self.port, "in_waiting", 0))
            data = bytes(self.port.read(waiting or 1)) if waiting or self.filenos() else b""
        except Exception:  # serial.SerialException, OSError: count, never raise in the loop
            self.errors += 1
            return []
        return [(data, self._key, False)] if data else []

    def write(self, data: bytes) -> bool:
        if len(self._out) > MAX_TCP_BACKLOG:
            self._flush()
            return False
        self._out += data
        self._flush()
        return True

    def _flush(self) -> None:
        if not self._out:
            return
        try:
            n = self.port.write(bytes(self._out))
            del self._out[: n or 0]
        except Exception:  # SerialTimeoutException when the line is full: keep the bytes
            self.errors += 1

    def close(self) -> None:
        self.port.close()


def open_link(url: str, baud: int = 115200) -> Link:
    """Open a link from its URL (see the module docstring)."""
    scheme, sep, rest = url.partition(":")
    if sep and scheme == "udpin":
        host, port = _split_hostport(rest, url, DEFAULT_SERVER_HOST)
        return UdpServerLink(url, host, port)
    if sep and scheme == "udpout":
        host, port = _split_hostport(rest, url, None)
        return UdpClientLink(url, host, port)
    if sep and scheme == "tcpin":
        host, port = _split_hostport(rest, url, DEFAULT_SERVER_HOST)
        return TcpServerLink(url, host, port)
    if sep and scheme == "tcp":
        host, port = _split_hostport(rest, url, None)
        return TcpClientLink(url, host, port)
    return SerialLink(url, baud)
