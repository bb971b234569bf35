"""A simulated autopilot and receiver for the live INS/GNSS vehicle (firmware_host/insgnss/).

The data of :func:`firmware_host.devtools.insgnss_sim.generate` (the same trajectory, IMU
errors, GNSS noise and faults as ``fdi-bridge sim insgnss`` on the same seed) go out on real
links: the IMU as MAVLink packets (``HIGHRES_IMU`` floats, or ``RAW_IMU`` in ArduPilot's mG and
mrad/s integers) with a ``SYSTEM_TIME`` every second, encoded by :mod:`drivers.mavlink.io`,
and the GNSS as NMEA (GGA + RMC, 1 Hz, ``gnss_latency_s`` after the epoch) on another link.
Each link is a byte writer (a :class:`~drivers.ptypair.PtyPair`'s master side in the tests).

The autopilot clock starts ``BOOT_S`` before the trajectory; UTC is :data:`UTC0` + t.
:class:`LinkImpairment` makes the IMU link a telemetry link: packets dropped at random,
duplicated, and held back in bursts (every ``burst_every_s`` the packets of ``burst_s`` wait and
go out together). ``speed`` plays the events that many times faster than real time (the
vehicle is paced by its data, its IMU ordering by the samples' own stamps).
"""

from __future__ import annotations

import calendar
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.gps.nmea import format_date, format_lat, format_lon, format_time, with_checksum
from drivers.mavlink.imu import MG_TO_M_S2, MRAD_TO_RAD
from drivers.mavlink.io import MavPacker
from fdi.geodesy import LocalFrame
from firmware_host.devtools.insgnss_sim import NavData

UTC0 = calendar.timegm((2026, 6, 1, 12, 0, 0))  # trajectory t = 0
DATE0 = (2026, 6, 1)
BOOT_S = 120.0  # autopilot uptime at t = 0
LON0_DEG = 8.5
H0_M = 300.0
KNOT_MPS = 1852.0 / 3600.0
Writer = Callable[[bytes], object]


@dataclass(frozen=True)
class LinkImpairment:
    drop: float = 0.0
    duplicate: float = 0.0
    burst_every_s: float = 0.0  # 0: no bursts
    burst_s: float = 0.2


def frame_of(latitude_deg: float) -> LocalFrame:
    """The simulator's tangent plane on the Earth (its origin)."""
    return LocalFrame(latitude_deg, LON0_DEG, H0_M)


def nmea_epoch(t_s: float, lla: tuple[float, float, float], v_enu: tuple[float, float]) -> bytes:
    utc = (UTC0 + t_s) % 86400.0
    ts = format_time(utc)
    la, ns = format_lat(lla[0])
    lo, ew = format_lon(lla[1])
    speed = math.hypot(v_enu[0], v_enu[1])
    course = math.degrees(math.atan2(v_enu[0], v_enu[1])) % 360.0
    gga = f"GPGGA,{ts},{la},{ns},{lo},{ew},1,12,0.8,{lla[2]:.3f},M,0.000,M,,"
    rmc = (f"GPRMC,{ts},A,{la},{ns},{lo},{ew},{speed / KNOT_MPS:.4f},{course:.3f},"
           f"{format_date(DATE0)},,,A")
    return with_checksum(gga) + with_checksum(rmc)


def build_events(data: NavData, latitude_deg: float, *, imu_message: str = "HIGHRES_IMU",
                 decimate: int = 1, impair: LinkImpairment | None = None, seed: int = 0,
                 gnss_latency_s: float = 0.05) -> list[tuple[float, int, bytes]]:
    """Every packet with its send time (s of trajectory time) and link (0 IMU, 1 GNSS), in
    send order."""
    imp = impair or LinkImpairment()
    rng = np.random.default_rng(seed)
    packer = MavPacker(source_system=1, source_component=1)
    events: list[tuple[float, int, int, bytes]] = []
    t = data.traj.t
    n_seq = 0

    def add(when: float, link: int, raw: bytes) -> None:
        nonlocal n_seq
        events.append((when, n_seq, link, raw))
        n_seq += 1

    end = float(t[-1])
    for s in range(int(end) + 1):
        add(float(s), 0, packer.send_system_time(round((UTC0 + s) * 1e6),
                                                 round((BOOT_S + s) * 1e3)))
    gyro, accel = data.gyro, data.accel
    for k in range(1, len(t), decimate):
        if decimate > 1:  # the mean over the longer interval (what an integrating IMU reports)
            lo = max(1, k - decimate + 1)
            g, a = gyro[lo:k + 1].mean(axis=0), accel[lo:k + 1].mean(axis=0)
        else:
            g, a = gyro[k], accel[k]
        tk = float(t[k])
        usec = round((BOOT_S + tk) * 1e6)
        if imu_message == "RAW_IMU":
            ai = (round(a[0] / MG_TO_M_S2), round(a[1] / MG_TO_M_S2), round(a[2] / MG_TO_M_S2))
            gi = (round(g[0] / MRAD_TO_RAD), round(g[1] / MRAD_TO_RAD), round(g[2] / MRAD_TO_RAD))
            raw = packer.send_raw_imu(usec, ai, gi)
        else:
            raw = packer.send_highres_imu(usec, (float(a[0]), float(a[1]), float(a[2])),
                                          (float(g[0]), float(g[1]), float(g[2])))
        if imp.drop and rng.random() < imp.drop:
            continue
        when = tk
        if imp.burst_every_s > 0:
            phase = tk % imp.burst_every_s
            if phase < imp.burst_s:
                when = tk - phase + imp.burst_s  # held, then out together
        add(when, 0, raw)
        if imp.duplicate and rng.random() < imp.duplicate:
            add(when, 0, raw)
    frame = frame_of(latitude_deg)
    for j in range(len(data.gnss_t)):
        p = data.gnss_p[j]
        lla = frame.to_lla(float(p[0]), float(p[1]), float(p[2]))
        v = data.gnss_v[j]
        add(float(data.gnss_t[j]) + gnss_latency_s, 1,
            nmea_epoch(float(data.gnss_t[j]), lla, (float(v[0]), float(v[1]))))
    events.sort(key=lambda e: (e[0], e[1]))
    return [(w, link, raw) for w, _, link, raw in events]


def play(events: list[tuple[float, int, bytes]], writers: tuple[Writer, Writer], *,
         speed: float = 10.0, stop: threading.Event | None = None,
         chunk_s: float = 0.01) -> int:
    """Write the events to the two links, ``speed`` times faster than real time; returns how
    many were written (fewer when ``stop`` is set)."""
    t0 = time.monotonic()
    i = 0
    n = len(events)
    while i < n:
        if stop is not None and stop.is_set():
            break
        base = events[i][0]
        bufs = [bytearray(), bytearray()]
        while i < n and events[i][0] < base + chunk_s:
            bufs[events[i][1]] += events[i][2]
            i += 1
        due = t0 + base / speed
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        for link in (0, 1):
            if bufs[link]:
                writers[link](bytes(bufs[link]))
    return i
