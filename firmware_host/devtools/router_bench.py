"""How much latency the MAVLink router adds per forwarded packet, over loopback UDP.

``fdi-bridge mavlink --bench [--bench-rate PPS ...] [--bench-seconds S] [--bench-runs N]``
prints one JSON line per run and rate.

Three processes, so that no measuring thread competes with the router for the GIL and nothing
spins on a core (the machine may have two):

* the **router** runs in this process, in its own thread, as ``fdi-bridge mavlink`` runs it;
* a **sender** process writes NAMED_VALUE_FLOAT packets to the router's autopilot port on
  absolute deadlines (``start + i / rate``), sleeping in between; a late sender sends what is
  due at once and does not shift the later deadlines. Each packet carries its number
  (``time_boot_ms``) and the ``CLOCK_MONOTONIC`` time it was sent, in nanoseconds (the first 8
  bytes of ``name``); its CRC is valid, so the router checks it as any other;
* a **receiver** process, a ground station seen by the router, blocks on its socket and
  subtracts the embedded send time from its receive time (the same system-wide clock).

Latency is from just before ``sendto`` in the sender to just after ``recv`` in the receiver.
The same pair run with the sender writing straight to the receiver gives the floor (two
processes waking up on loopback, no router), reported as ``direct_*``; the router's
``added_*`` are the routed percentiles minus the direct ones. ``router_cpu_pct`` is this
process's CPU time over the run (the router thread is the only busy one).
"""

from __future__ import annotations

import multiprocessing as mp
import resource
import socket
import struct
import time
from typing import Any

import numpy as np

from drivers.mavlink import io as mio
from drivers.mavlink.framer import x25crc
from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig, Router

_MSGID = mio.message_id("NAMED_VALUE_FLOAT")
_EXTRA = mio.crc_extra(_MSGID)
_TAG = b"BN"  # the last two bytes of ``name``: marks a benchmark packet
_PAYLOAD = struct.Struct("<Ifq2s")  # time_boot_ms, value, name[0:8] = send time ns, name[8:10]
_HEADER = struct.Struct("<BBBBBBBHB")  # magic len incompat compat seq sys comp msgid(lo16, hi8)


def bench_packet(i: int, sent_ns: int) -> bytes:
    """A MAVLink 2 NAMED_VALUE_FLOAT numbered ``i`` carrying ``sent_ns``, with a valid CRC."""
    assert _EXTRA is not None
    payload = _PAYLOAD.pack(i & 0xFFFFFFFF, 1.0, sent_ns, _TAG)
    header = _HEADER.pack(0xFD, len(payload), 0, 0, i & 0xFF, 1, 1, _MSGID & 0xFFFF, _MSGID >> 16)
    body = header + payload
    return body + struct.pack("<H", x25crc(body[1:] + bytes((_EXTRA,))))


def parse_bench_packet(data: bytes) -> tuple[int, int] | None:
    """``(number, sent_ns)`` of a benchmark packet, None for anything else."""
    if len(data) != 10 + _PAYLOAD.size + 2 or data[0] != 0xFD or data[7] != _MSGID:
        return None
    i, _, sent_ns, tag = _PAYLOAD.unpack_from(data, 10)
    return (i, sent_ns) if tag == _TAG else None


def _sender(conn: Any, port: int, rate_pps: int, n: int) -> None:
    """Send ``n`` packets to 127.0.0.1:``port`` on absolute deadlines; report lateness."""
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    dest = ("127.0.0.1", port)
    period_ns = round(1e9 / rate_pps)
    conn.recv()  # go
    now_ns = time.monotonic_ns
    start = now_ns() + 10_000_000
    late = 0
    for i in range(n):
        due = start + i * period_ns
        t = now_ns()
        if t < due:
            time.sleep((due - t) * 1e-9)
        elif t - due > period_ns:
            late += 1
        tx.sendto(bench_packet(i, now_ns()), dest)
    tx.close()
    conn.send({"late": late, "send_s": (now_ns() - start) * 1e-9})


def _receiver(conn: Any, gcs_port: int | None, n: int, deadline_s: float) -> None:
    """Be a ground station: say hello to the router (if any), then time every packet."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    rx.bind(("127.0.0.1", 0))
    if gcs_port is not None:
        rx.sendto(mio.MavPacker(255, 190).send_heartbeat(), ("127.0.0.1", gcs_port))
    conn.send(rx.getsockname()[1])
    lat_ns = np.full(n, -1, dtype=np.int64)
    order_ok = True
    last = -1
    got = 0
    other = 0
    rx.settimeout(0.1)
    end = time.monotonic() + deadline_s
    now_ns = time.monotonic_ns
    while got < n and time.monotonic() < end:
        try:
            data = rx.recv(65535)
        except TimeoutError:
            continue
        t = now_ns()
        parsed = parse_bench_packet(data)
        if parsed is None:
            other += 1  # the router's heartbeat
            continue
        i, sent_ns = parsed
        if i < n and lat_ns[i] < 0:
            lat_ns[i] = t - sent_ns
            got += 1
            order_ok = order_ok and i > last
            last = i
    rx.close()
    conn.send({"lat_ns": lat_ns, "in_order": order_ok, "other": other})


def _percentiles(lat_ns: np.ndarray) -> dict[str, float]:
    ok = lat_ns[lat_ns >= 0] * 1e-6
    if not ok.size:
        return {k: float("nan") for k in ("p50_ms", "p90_ms", "p99_ms", "p999_ms", "max_ms")}
    p50, p90, p99, p999 = np.percentile(ok, [50, 90, 99, 99.9])
    return {"p50_ms": float(p50), "p90_ms": float(p90), "p99_ms": float(p99),
            "p999_ms": float(p999), "max_ms": float(ok.max())}  # fmt: skip


def _measure(rate_pps: int, seconds: float, router: Router | None) -> dict[str, Any]:
    ctx = mp.get_context("spawn")
    n = max(1, int(rate_pps * seconds))
    gcs_port = None
    if router is not None:
        addr = router.endpoints[1].link.local_address
        assert addr is not None
        gcs_port = addr[1]
    r_parent, r_child = ctx.Pipe()
    s_parent, s_child = ctx.Pipe()
    receiver = ctx.Process(target=_receiver, args=(r_child, gcs_port, n, seconds + 10.0))
    receiver.start()
    try:
        rx_port = int(r_parent.recv())
        if router is not None:
            end = time.monotonic() + 5.0
            while not router.endpoints[1].link.has_peer():  # the receiver's hello, routed
                if time.monotonic() > end:
                    raise RuntimeError("the benchmark receiver was not seen by the router")
                time.sleep(0.001)
            ap_addr = router.endpoints[0].link.local_address
            assert ap_addr is not None
            target = ap_addr[1]
        else:
            target = rx_port
        sender = ctx.Process(target=_sender, args=(s_child, target, rate_pps, n))
        sender.start()
        cpu0 = resource.getrusage(resource.RUSAGE_SELF)
        s_parent.send("go")
        sent_info = s_parent.recv()
        got = r_parent.recv()
        cpu1 = resource.getrusage(resource.RUSAGE_SELF)
        sender.join(timeout=10)
    finally:
        receiver.join(timeout=10)
        if receiver.is_alive():
            receiver.terminate()
    lat_ns = got["lat_ns"]
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    out: dict[str, Any] = {
        "sent": n,
        "received": int((lat_ns >= 0).sum()),
        "in_order": bool(got["in_order"]),
        "sender_late": int(sent_info["late"]),
        "send_s": round(float(sent_info["send_s"]), 3),
        "cpu_pct": round(100.0 * cpu / max(1e-9, float(sent_info["send_s"])), 1),
    }
    out.update(_percentiles(lat_ns))
    return out


def bench_forwarding(rate_pps: int, seconds: float) -> dict[str, float | int | bool]:
    """Added latency per forwarded packet at ``rate_pps`` for ``seconds`` (see the module doc)."""
    direct = _measure(rate_pps, seconds, None)
    cfg = MavlinkConfig(
        autopilot=EndpointConfig("udpin:127.0.0.1:0"),
        gcs=(EndpointConfig("udpin:127.0.0.1:0"),),
        stats_hz=0.0,
        queue_packets=max(2000, rate_pps),
    )
    router = Router(cfg)
    try:
        router.start()
        routed = _measure(rate_pps, seconds, router)
        s = router.summary()
    finally:
        router.close()
    result: dict[str, float | int | bool] = {"rate_pps": rate_pps, "seconds": seconds}
    for k in ("sent", "received", "in_order", "sender_late"):
        result[k] = routed[k]
    result["lost"] = int(routed["sent"]) - int(routed["received"])
    for k in ("p50_ms", "p90_ms", "p99_ms", "p999_ms", "max_ms"):
        result[k] = round(float(routed[k]), 4)
        result[f"direct_{k}"] = round(float(direct[k]), 4)
    for k in ("p50_ms", "p99_ms"):
        result[f"added_{k}"] = round(float(routed[k]) - float(direct[k]), 4)
    result["router_cpu_pct"] = routed["cpu_pct"]
    result["router_queue_drops"] = int(s["gcs0"]["dropped_queue_full"])
    result["router_bad_crc"] = int(s["bad_crc"])
    return result
