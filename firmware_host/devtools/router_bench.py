"""How much latency the MAVLink router adds per forwarded packet, over loopback UDP.

``fdi-bridge mavlink --bench [--bench-rate PPS ...] [--bench-seconds S] [--bench-runs N]``
prints one JSON line per run and rate (:func:`run`: the command line's door to developer tools,
:mod:`firmware_host.cli`, sends ``mavlink --bench`` here; the options are ``mavlink``'s).

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

import argparse
import json
import multiprocessing as mp
import resource
import socket
import struct
import threading
import time
from dataclasses import replace
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


def bench_packet(i: int, sent_ns: int, source: tuple[int, int] = (1, 1)) -> bytes:
    """A MAVLink 2 NAMED_VALUE_FLOAT numbered ``i`` carrying ``sent_ns``, with a valid CRC,
    from ``source`` (system, component)."""
    assert _EXTRA is not None
    payload = _PAYLOAD.pack(i & 0xFFFFFFFF, 1.0, sent_ns, _TAG)
    header = _HEADER.pack(0xFD, len(payload), 0, 0, i & 0xFF, *source, _MSGID & 0xFFFF,
                          _MSGID >> 16)
    body = header + payload
    return body + struct.pack("<H", x25crc(body[1:] + bytes((_EXTRA,))))


def parse_bench_packet(data: bytes) -> tuple[int, int] | None:
    """``(number, sent_ns)`` of a benchmark packet, None for anything else."""
    if len(data) != 10 + _PAYLOAD.size + 2 or data[0] != 0xFD or data[7] != _MSGID:
        return None
    i, _, sent_ns, tag = _PAYLOAD.unpack_from(data, 10)
    return (i, sent_ns) if tag == _TAG else None


def _sender(conn: Any, port: int, rate_pps: int, n: int,
            source: tuple[int, int] = (1, 1)) -> None:
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
        tx.sendto(bench_packet(i, now_ns(), source), dest)
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


# ---------------------------------------------------------------------------------------------
# GPS_INPUT under a ground-station flood (issue C item 7)

_GPS_INPUT = mio.message_id("GPS_INPUT")
FLOOD_GOAL_P99_MS = 20.0
"""Issue C's goal for the p99 of GPS_INPUT's latency to the autopilot under the flood."""


def _autopilot(conn: Any, router_port: int, deadline_s: float) -> None:
    """Be the autopilot: say hello to the router, then read everything until told to stop;
    time each GPS_INPUT (its ``time_usec`` is the CLOCK_MONOTONIC µs it was handed over at)
    and count the flood's packets."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    rx.bind(("127.0.0.1", 0))
    rx.sendto(mio.MavPacker(1, 1).send_heartbeat(), ("127.0.0.1", router_port))
    conn.send(rx.getsockname()[1])
    lat_us: list[int] = []
    direct_us: list[int] = []
    flood = 0
    gps_lo, gps_hi = _GPS_INPUT & 0xFF, _GPS_INPUT >> 8
    rx.settimeout(0.1)
    end = time.monotonic() + deadline_s
    now_ns = time.monotonic_ns
    while time.monotonic() < end and not conn.poll():
        try:
            data = rx.recv(65535)
        except TimeoutError:
            continue
        t_us = now_ns() // 1000
        if len(data) > 18 and data[0] == 0xFD and data[7] == gps_lo and data[8] == gps_hi:
            dest = direct_us if data[6] == _DIRECT_COMPID else lat_us
            dest.append(t_us - int.from_bytes(data[10:18], "little"))
        elif len(data) > 10 and data[7] == _MSGID:
            flood += 1
    rx.close()
    conn.send({"lat_us": lat_us, "direct_us": direct_us, "flood": flood})


_DIRECT_COMPID = 192  # the feeder's fixes sent straight to the autopilot (the floor)


def bench_gps_input_under_flood(rate_pps: int = 20000, seconds: float = 20.0,
                                gps_hz: float = 20.0) -> dict[str, Any]:
    """GPS_INPUT latency to the autopilot while a ground station floods the router.

    The router runs in this process as ``fdi-bridge run`` runs it (its own thread); a thread
    hands it a GPS_INPUT every ``1 / gps_hz`` s on absolute deadlines, as the rover's pipeline
    does, stamped with CLOCK_MONOTONIC in ``time_usec``, and sends the same fix straight to the
    autopilot on a socket of its own (component 192; ``direct_*``: this machine's floor, GIL
    and scheduling included, without the router); a **flood** process sends
    ``rate_pps`` NAMED_VALUE_FLOAT/s from the ground station's ids (255, 190) to the router's
    ground-station port for ``seconds`` (127.0.0.1 only; bounded), all forwarded towards the
    autopilot; an **autopilot** process reads everything and times each GPS_INPUT from
    hand-over to its ``recv``. Reported: GPS_INPUT p50/p99/max, how many arrived, and the
    router's drops per endpoint (queue, send buffer, and the kernel's receive drops: what the
    router could not read in time).
    """
    ctx = mp.get_context("spawn")
    cfg = MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"),
                        gcs=(EndpointConfig("udpin:127.0.0.1:0"),), stats_hz=0.0)
    router = Router(cfg)
    n = max(1, int(rate_pps * seconds))
    a_parent, a_child = ctx.Pipe()
    s_parent, s_child = ctx.Pipe()
    handed = 0
    try:
        router.start()
        ap_addr = router.endpoints[0].link.local_address
        gcs_addr = router.endpoints[1].link.local_address
        assert ap_addr is not None and gcs_addr is not None
        ap = ctx.Process(target=_autopilot, args=(a_child, ap_addr[1], seconds + 30.0))
        ap.start()
        ap_port = int(a_parent.recv())
        end = time.monotonic() + 5.0
        while not router.autopilot.link.has_peer():
            if time.monotonic() > end:
                raise RuntimeError("the benchmark's autopilot was not seen by the router")
            time.sleep(0.001)
        flood = ctx.Process(target=_sender, args=(s_child, gcs_addr[1], rate_pps, n, (255, 190)))
        flood.start()
        halt = False

        def feed() -> None:  # the pipeline's thread: one fix per period, absolute deadlines
            nonlocal handed
            period = 1.0 / gps_hz
            t_next = time.monotonic()
            direct = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            packer = mio.MavPacker(1, _DIRECT_COMPID)
            while not halt:
                t_next += period
                time.sleep(max(0.0, t_next - time.monotonic()))
                fix = mio.GpsInputFix(time.monotonic_ns() // 1000, 2300, 0, 3, 32.0, 118.0, 10.0,
                                      0.9, None, None, None, None, 0.1, 0.5, 1.0, 10)
                router.send_gps_input(fix)
                handed += 1
                fix = replace(fix, time_usec=time.monotonic_ns() // 1000)
                direct.sendto(packer.send_gps_input(fix), ("127.0.0.1", ap_port))
            direct.close()

        feeder = threading.Thread(target=feed, name="bench-gps-input", daemon=True)
        s_parent.send("go")
        feeder.start()
        sent_info = s_parent.recv()
        halt = True
        feeder.join(timeout=2.0)
        flood.join(timeout=10)
        time.sleep(0.2)  # the last packets in flight
        a_parent.send("stop")
        got = a_parent.recv()
        ap.join(timeout=10)
        s = router.summary()
    finally:
        router.close()
    lat_ms = np.asarray(got["lat_us"], dtype=float) * 1e-3
    direct_ms = np.asarray(got["direct_us"], dtype=float) * 1e-3
    out: dict[str, Any] = {"rate_pps": rate_pps, "seconds": seconds, "gps_hz": gps_hz,
                           "flood_sent": n, "flood_send_s": round(float(sent_info["send_s"]), 3),
                           "flood_at_autopilot": int(got["flood"]), "gps_handed": handed,
                           "gps_received": int(lat_ms.size)}
    if lat_ms.size:
        p50, p99 = np.percentile(lat_ms, [50, 99])
        out.update(p50_ms=round(float(p50), 3), p99_ms=round(float(p99), 3),
                   max_ms=round(float(lat_ms.max()), 3))
    if direct_ms.size:
        p50, p99 = np.percentile(direct_ms, [50, 99])
        out.update(direct_p50_ms=round(float(p50), 3), direct_p99_ms=round(float(p99), 3),
                   direct_max_ms=round(float(direct_ms.max()), 3))
    out["drops"] = {name: {k: s[name][k] for k in _DROP_KEYS if k in s[name]}
                    for name in ("autopilot", "gcs0")}
    return out


_DROP_KEYS = ("rx_packets", "tx_packets", "dropped_queue_full", "dropped_own", "send_dropped",
              "rx_kernel_drops", "no_peer")


def run(args: argparse.Namespace) -> int:
    """``fdi-bridge mavlink --bench``: one JSON line per run and rate."""
    for rate in args.bench_rate or (1000, 10000):
        for _ in range(max(1, args.bench_runs)):
            print(json.dumps(bench_forwarding(rate, args.bench_seconds)), flush=True)
    return 0
