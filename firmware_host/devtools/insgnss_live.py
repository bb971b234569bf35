"""A simulated autopilot and receiver for the live INS/GNSS vehicle (firmware_host/insgnss/).

The data of :func:`firmware_host.devtools.insgnss_sim.generate` (the same trajectory, IMU
errors, GNSS noise and faults as ``fdi-bridge sim insgnss`` on the same seed) go out on real
links: the IMU as MAVLink packets (``HIGHRES_IMU`` floats, or ``RAW_IMU`` in ArduPilot's mG and
mrad/s integers) with a ``SYSTEM_TIME`` every second, encoded by :mod:`drivers.mavlink.io`,
and the GNSS as NMEA (GGA + RMC, 1 Hz, ``gnss_latency_s`` after the epoch) on another link.
Each link is a byte writer (a :class:`~drivers.ptypair.PtyPair`'s master side in the tests).

The autopilot clock starts ``BOOT_S`` before the data (the lead-in's start when
``[insgnss.sim] rest_s`` gives one: then the data begin at rest, t < 0); UTC is
:data:`UTC0` + t.
:class:`LinkImpairment` makes the IMU link a telemetry link: packets dropped at random,
duplicated, and held back in bursts (every ``burst_every_s`` the packets of ``burst_s`` wait and
go out together). ``speed`` plays the events that many times faster than real time (the
vehicle is paced by its data, its IMU ordering by the samples' own stamps).
"""

from __future__ import annotations

import array
import calendar
import fcntl
import json
import math
import socket
import termios
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from drivers.gps.nmea import format_date, format_lat, format_lon, format_time, with_checksum
from drivers.mavlink.framer import MavFramer
from drivers.mavlink.imu import MG_TO_M_S2, MRAD_TO_RAD
from drivers.mavlink.io import MavPacker
from drivers.ptypair import PtyPair
from fdi.geodesy import LocalFrame
from fdi.insgnss import InsGnssFilter, InsGnssParams, InsGnssStrategy
from firmware_host.devtools.insgnss_sim import (
    SIM_BOOT_S,
    MethodRun,
    NavData,
    Scenario,
    generate,
    run_method,
    summarize,
)
from firmware_host.insgnss import align
from firmware_host.insgnss.vehicle import ROUTER, InsGnssVehicle
from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig, Router, open_router
from firmware_host.runtime.config import BridgeConfig
from firmware_host.runtime.config_insgnss import InsGnssSetup
from firmware_host.runtime.recorder import FlightRecorder, RecorderConfig
from firmware_host.runtime.runner import Runner

UTC0 = calendar.timegm((2026, 6, 1, 12, 0, 0))  # trajectory t = 0
DATE0 = (2026, 6, 1)
BOOT_S = SIM_BOOT_S  # autopilot uptime at the data's start (gyro_drift counts from it)
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
    shuffle_bursts: bool = False  # a held burst goes out in random order (a UDP link)
    thin_from_s: float | None = None  # from this trajectory time on, only every
    thin_keep: int = 1  # ``thin_keep``-th IMU packet goes out (a link that slows down)


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


def nmea_no_fix(t_s: float) -> bytes:
    """The epoch of a receiver that has lost its fix (a GNSS outage): GGA quality 0 and RMC
    status V, the time but no position, as receivers send it."""
    ts = format_time((UTC0 + t_s) % 86400.0)
    return (with_checksum(f"GPGGA,{ts},,,,,0,00,99.99,,,,,,")
            + with_checksum(f"GPRMC,{ts},V,,,,,,,{format_date(DATE0)},,,N"))


def _spans(outage: tuple[float, float] | Sequence[tuple[float, float]] | None,
           ) -> list[tuple[float, float]]:
    if outage is None:
        return []
    if len(outage) == 2 and all(isinstance(x, float | int) for x in outage):
        a, b = outage
        return [(float(a), float(b))]  # type: ignore[arg-type]
    return [(float(a), float(b)) for a, b in outage]  # type: ignore[misc]


def build_events(data: NavData, latitude_deg: float, *, imu_message: str = "HIGHRES_IMU",
                 decimate: int = 1, impair: LinkImpairment | None = None, seed: int = 0,
                 gnss_latency_s: float = 0.05, attitude_error_deg: float | None = None,
                 outage: tuple[float, float] | Sequence[tuple[float, float]] | None = None,
                 ) -> list[tuple[float, int, bytes]]:
    """Every packet with its send time (s of trajectory time) and link (0 IMU, 1 GNSS), in
    send order. ``attitude_error_deg``: also ATTITUDE at 10 Hz on the IMU link, the
    autopilot's own estimate, modelled as the attitude with a constant heading error of that
    many degrees (a compass error). ``outage``: the GNSS epochs with ``t0 <= t < t1``
    (trajectory time; or several such spans) are no-fix epochs (:func:`nmea_no_fix`)."""
    imp = impair or LinkImpairment()
    spans = _spans(outage)
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
    boot = BOOT_S + data.lead  # autopilot uptime at t = 0
    for s in range(-data.lead, int(end) + 1):
        add(float(s), 0, packer.send_system_time(round((UTC0 + s) * 1e6),
                                                 round((boot + s) * 1e3)))
    gyro, accel = data.gyro, data.accel
    for k in range(1, len(t), decimate):
        if decimate > 1:  # the mean over the longer interval (what an integrating IMU reports)
            lo = max(1, k - decimate + 1)
            g, a = gyro[lo:k + 1].mean(axis=0), accel[lo:k + 1].mean(axis=0)
        else:
            g, a = gyro[k], accel[k]
        tk = float(t[k])
        usec = round((boot + tk) * 1e6)
        if imu_message == "RAW_IMU":
            ai = (round(a[0] / MG_TO_M_S2), round(a[1] / MG_TO_M_S2), round(a[2] / MG_TO_M_S2))
            gi = (round(g[0] / MRAD_TO_RAD), round(g[1] / MRAD_TO_RAD), round(g[2] / MRAD_TO_RAD))
            raw = packer.send_raw_imu(usec, ai, gi)
        else:
            raw = packer.send_highres_imu(usec, (float(a[0]), float(a[1]), float(a[2])),
                                          (float(g[0]), float(g[1]), float(g[2])))
        if imp.drop and rng.random() < imp.drop:
            continue
        if imp.thin_from_s is not None and tk >= imp.thin_from_s and k % imp.thin_keep:
            continue
        when = tk
        if imp.burst_every_s > 0:
            phase = (tk + data.lead) % imp.burst_every_s
            if phase < imp.burst_s:
                when = tk - phase + imp.burst_s  # held, then out together
                if imp.shuffle_bursts:
                    when += float(rng.random()) * 1e-3
        add(when, 0, raw)
        if imp.duplicate and rng.random() < imp.duplicate:
            add(when, 0, raw)
    if attitude_error_deg is not None:
        rpy = data.traj.rpy
        for k in range(0, len(t), 10):
            tk = float(t[k])
            add(tk, 0, packer.send_attitude(round((boot + tk) * 1e3), float(rpy[k, 0]),
                                            float(rpy[k, 1]),
                                            float(rpy[k, 2]) + math.radians(attitude_error_deg)))
    frame = frame_of(latitude_deg)
    for j in range(len(data.gnss_t)):
        tj = float(data.gnss_t[j])
        if any(a <= tj < b for a, b in spans):
            add(tj + gnss_latency_s, 1, nmea_no_fix(tj))
            continue
        p = data.gnss_p[j]
        lla = frame.to_lla(float(p[0]), float(p[1]), float(p[2]))
        v = data.gnss_v[j]
        add(float(data.gnss_t[j]) + gnss_latency_s, 1,
            nmea_epoch(float(data.gnss_t[j]), lla, (float(v[0]), float(v[1]))))
    events.sort(key=lambda e: (e[0], e[1]))
    return [(w, link, raw) for w, _, link, raw in events]


def play(events: list[tuple[float, int, bytes]], writers: tuple[Writer, Writer], *,
         speed: float = 10.0, stop: threading.Event | None = None,
         chunk_s: float = 0.01, gnss_after_s: float = 0.3,
         drained: Callable[[], bool] | None = None, drain_timeout_s: float = 60.0) -> int:
    """Write the events to the two links, ``speed`` times faster than real time from the
    first event; returns how many were written (fewer when ``stop`` is set). The receiver's
    bytes wait until the IMU has streamed ``gnss_after_s`` of wall clock (an autopilot is up
    before the receiver's first fix), so that which link the vehicle reads first does not
    depend on the scheduler. ``drained``: each chunk waits until it says the reader has kept
    up (at most ``drain_timeout_s``), so that the reader's lag is bounded however slow the
    machine (at 50x a loaded machine fell over 1 s of wall clock behind, the vehicle's
    ``max_wait_s``, and gave up on the IMU of an epoch)."""
    t0 = time.monotonic()
    t_first = events[0][0] if events else 0.0
    i = 0
    n = len(events)
    held = bytearray()
    while i < n:
        if stop is not None and stop.is_set():
            break
        base = events[i][0]
        bufs = [bytearray(), bytearray()]
        while i < n and events[i][0] < base + chunk_s:
            bufs[events[i][1]] += events[i][2]
            i += 1
        due = t0 + (base - t_first) / speed
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        if drained is not None:
            give_up = time.monotonic() + drain_timeout_s
            while not drained() and time.monotonic() < give_up:
                if stop is not None and stop.is_set():
                    return i
                time.sleep(0.0005)
        if bufs[0]:
            writers[0](bytes(bufs[0]))
        held += bufs[1]
        if held and (time.monotonic() - t0 >= gnss_after_s or i >= n):
            writers[1](bytes(held))
            held.clear()
    return i


# ---------------------------------------------------------------- a whole live session


@dataclass
class LiveRun:
    """One live session: the vehicle's summary and records, and its position errors at the
    epochs the INS produced (``epochs``: GNSS epoch numbers)."""

    summary: dict[str, Any]
    records: list[dict[str, Any]]
    epochs: npt.NDArray[np.int_]
    pos_err: npt.NDArray[np.float64]
    wall_s: float
    coast: CoastReport | None = None  # with an outage (:func:`compare`)
    status: tuple[str, ...] = ()  # the vehicle's status line section at the end


LAG_S = 1.0  # the vehicle's largest lag behind the player, s of data


def unread(pair: PtyPair) -> int:
    """Bytes written to ``pair`` that the port on its slave side has not read yet."""
    n = array.array("i", [0])
    fcntl.ioctl(pair.slave_fd, termios.TIOCINQ, n)
    return n[0]


def run_live(setup: InsGnssSetup, data: NavData, out_dir: Path, *,
             imu_message: str = "HIGHRES_IMU", decimate: int = 1,
             impair: LinkImpairment | None = None, seed: int = 0,
             speed: float = 50.0, mavlink_url: str = "", nmea_url: str = "",
             record_dir: Path | None = None, via_router: bool = False,
             attitude_error_deg: float | None = None,
             outage: tuple[float, float] | Sequence[tuple[float, float]] | None = None,
             imu_socket: bool = False) -> LiveRun:
    """Play ``data`` to an :class:`~firmware_host.insgnss.vehicle.InsGnssVehicle` on a
    :class:`~firmware_host.runtime.runner.Runner` over two real ptys (GNSS NMEA, MAVLink IMU);
    ``out_dir`` gets its ``epochs.jsonl`` and ``summary.json``; ``mavlink_url`` / ``nmea_url``:
    the vehicle's GPS_INPUT and corrected NMEA outputs; ``record_dir``: a flight recorder there
    (both inputs, for ``fdi-bridge replay``); ``via_router``: the IMU over UDP on 127.0.0.1 to
    the autopilot link of a ``[mavlink]`` router, ``imu_url = "router"``, one datagram a
    packet (GPS_INPUT then goes out through the router too); ``outage``: a GNSS outage
    (:func:`build_events`); ``imu_socket``: the IMU link is a TCP connection on 127.0.0.1
    (``imu_url = "socket://127.0.0.1:PORT"``, the autopilot's side listening as SITL's TCP
    ports do) instead of a pty."""
    lat = setup.filter.latitude_deg
    events = build_events(data, lat, imu_message=imu_message, decimate=decimate,
                          impair=impair, seed=seed, attitude_error_deg=attitude_error_deg,
                          outage=outage)
    base = BridgeConfig()
    rc = base.rover
    rover = replace(rc, port=replace(rc.port, timeout_s=0.02),
                    output=replace(rc.output, nmea_url=nmea_url, mavlink_url=mavlink_url))
    mav = MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"),
                        gcs=(EndpointConfig("udpin:127.0.0.1:0"),)) if via_router else None
    with PtyPair() as gps, PtyPair() as imu, socket.socket(socket.AF_INET,
                                                           socket.SOCK_DGRAM) as udp, \
            socket.create_server(("127.0.0.1", 0)) as server:
        cfg = replace(base, rover=replace(rover, port=replace(rover.port, url=gps.url)))
        imu_url = imu.url
        if via_router:
            imu_url = ROUTER
        elif imu_socket:
            imu_url = f"socket://127.0.0.1:{server.getsockname()[1]}"
        live = replace(setup, live=replace(setup.live, imu_url=imu_url,
                                           imu_message=imu_message))  # type: ignore[arg-type]
        vehicle = InsGnssVehicle(cfg, live)
        recorder = None if record_dir is None else FlightRecorder(
            record_dir, RecorderConfig(dir=str(record_dir)))
        runner = Runner(vehicle, out_dir=out_dir, recorder=recorder, mavlink=mav,
                        open_router=open_router, handle_signals=False)
        imu_write: Writer = imu.write
        runner.start()  # the ports (and the router's autopilot port) open before anything is sent
        if via_router:
            assert isinstance(runner.router, Router)
            addr = runner.router.endpoints[0].link.local_address
            assert addr is not None
            ap = ("127.0.0.1", int(addr[1]))

            def imu_write(data: bytes) -> None:  # one datagram per packet, as an autopilot
                for frame in MavFramer().feed(data):
                    udp.sendto(frame.raw, ap)
        done = threading.Event()
        stop = threading.Event()
        conns: list[socket.socket] = []

        # Over the ptys the player waits while the vehicle has more than LAG_S of data unread.
        span = events[-1][0] - events[0][0] if events else 0.0
        budget = LAG_S * sum(len(e[2]) for e in events) / max(span, LAG_S)

        def kept_up() -> bool:
            return unread(gps) + unread(imu) <= budget

        def feed() -> None:
            writer = imu_write
            try:
                if imu_socket:  # the vehicle's port connects to the autopilot's listener
                    server.settimeout(10.0)
                    conn, _ = server.accept()
                    conns.append(conn)  # closed once the runner has stopped
                    writer = conn.sendall
                play(events, (writer, gps.write), speed=speed, stop=stop,
                     drained=None if via_router else kept_up)
            finally:
                done.set()

        ended: list[float] = []

        def until() -> bool:  # everything played and read, then 0.5 s for the last epoch
            if not done.is_set() or unread(gps) or (not via_router and unread(imu)):
                return False
            if not ended:
                ended.append(time.monotonic())
            return time.monotonic() - ended[0] > 0.5

        thread = threading.Thread(target=feed, daemon=True)
        t0 = time.monotonic()
        thread.start()
        try:
            summary = runner.run(until=until)
        finally:
            stop.set()
            thread.join(5.0)
            for conn in conns:
                conn.close()
        wall = time.monotonic() - t0
    records = [json.loads(line) for line in
               (out_dir / "epochs.jsonl").read_text(encoding="utf-8").splitlines()]
    epochs, errs = live_errors(records, data, lat, setup.sim.imu_rate_hz)
    return LiveRun(summary, records, epochs, errs, wall, status=vehicle.status_detail())


def live_errors(records: list[dict[str, Any]], data: NavData, latitude_deg: float,
                rate_hz: int) -> tuple[npt.NDArray[np.int_], npt.NDArray[np.float64]]:
    """Position error (E, N, U, m, against the truth in the simulator's frame) of every epoch
    the INS produced after the lead-in (the paper's epochs 1..; ``epochs``: their numbers)."""
    frame = frame_of(latitude_deg)
    t_day0 = (UTC0 % 86400.0)
    js: list[int] = []
    errs: list[tuple[float, float, float]] = []
    for r in records:
        ins = r.get("ins")
        if r.get("mode") != "ins" or not isinstance(ins, dict) or "lla" not in ins:
            continue
        j = round((float(r["t"]) - t_day0 + 43200.0) % 86400.0 - 43200.0)
        if j < 1:
            continue  # the lead-in
        e, n, u = frame.to_enu(*ins["lla"])
        p = data.traj.p[(j + data.lead) * rate_hz]
        js.append(j)
        errs.append((e - float(p[0]), n - float(p[1]), u - float(p[2])))
    return np.array(js, dtype=int), np.array(errs, dtype=float).reshape(-1, 3)


def offline_aligned(data: NavData, params: InsGnssParams, j0: int,
                    strategy: InsGnssStrategy | None = None,
                    course_sigma_deg: float = 1.0) -> npt.NDArray[np.float64]:
    """The offline filter on the same data, aligned in motion as the live vehicle aligns (at
    GNSS epoch ``j0``: the fix's position, the horizontal GNSS velocity along its course,
    level from the mean specific force over the last second, heading from the course, the
    initial covariance of :func:`firmware_host.insgnss.align.in_motion`), position updates
    only; its position errors at epochs ``j0 + 1 ..`` (data without a lead-in)."""
    prm = replace(params, use_velocity=False, strategy=strategy or params.strategy)
    rate = round(1.0 / float(data.traj.t[1] - data.traj.t[0]))
    k0 = j0 * rate
    f = data.accel[k0 - rate + 1:k0 + 1].mean(axis=0)
    v = data.gnss_v[j0]
    a = align.in_motion(prm, f, 1.0, math.hypot(float(v[0]), float(v[1])),
                        math.atan2(float(v[0]), float(v[1])), course_sigma_deg)
    kf = InsGnssFilter(a.params(prm), float(data.gnss_t[j0]), data.gnss_p[j0],
                       (float(v[0]), float(v[1]), 0.0), (a.roll, a.pitch, a.yaw))
    t = data.traj.t.tolist()
    gyro, accel = data.gyro.tolist(), data.accel.tolist()
    out = []
    for j in range(j0 + 1, len(data.gnss_t)):
        for k in range((j - 1) * rate + 1, j * rate + 1):
            kf.propagate(t[k], gyro[k], accel[k])
        kf.update(float(data.gnss_t[j]), data.gnss_p[j])
        out.append(kf.position - data.traj.p[j * rate])
    return np.array(out)


@dataclass(frozen=True)
class CoastReport:
    """A GNSS outage through the live vehicle: epochs the INS's coast went out as a 3D fix,
    epochs sent as no-fix past the coast limit, and the largest true horizontal error over
    the horizontal accuracy sent (issue G: at most 2)."""

    sent: int
    no_fix: int
    worst_ratio: float
    worst_err_m: float


def coast_report(records: list[dict[str, Any]], data: NavData, latitude_deg: float,
                 rate_hz: int) -> CoastReport:
    """The coast epochs of ``records`` (``ins.coast_s``) against the truth (the trajectory at
    the record's time)."""
    frame = frame_of(latitude_deg)
    day0 = UTC0 % 86400.0
    sent = no_fix = 0
    worst_ratio = worst_err = 0.0
    for r in records:
        ins = r.get("ins")
        if r.get("mode") != "ins" or not isinstance(ins, dict) or "coast_s" not in ins:
            continue
        if ins.get("output") == "no fix":
            no_fix += 1
            continue
        t = (float(r["t"]) - day0 + 43200.0) % 86400.0 - 43200.0
        p = data.traj.p[round((t - float(data.traj.t[0])) * rate_hz)]
        e, n, _ = frame.to_enu(*ins["lla"])
        err = float(np.hypot(e - p[0], n - p[1]))
        sent += 1
        worst_err = max(worst_err, err)
        worst_ratio = max(worst_ratio, err / max(float(ins["acc_h_m"]), 1e-9))
    return CoastReport(sent, no_fix, worst_ratio, worst_err)


def rms(err: npt.NDArray[np.float64]) -> float:
    """The 3D position RMS (m)."""
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1))))


@dataclass
class Comparison:
    """The live vehicle against ``sim insgnss`` (the offline filter, started from the truth
    plus its initial sigmas) on the same scenario and seed: 3-D position RMS (m) over the
    paper's epochs each produced."""

    scenario: str
    seed: int
    live_rms_m: float
    offline_rms_m: float
    none_rms_m: float  # the offline filter without robust treatment
    live_epochs: int
    offline_epochs: int
    run: LiveRun

    @property
    def ratio(self) -> float:
        """live / offline."""
        return self.live_rms_m / self.offline_rms_m

    @property
    def factor_live(self) -> float:
        """How far below "none" the live vehicle is (none / live)."""
        return self.none_rms_m / self.live_rms_m

    @property
    def factor_offline(self) -> float:
        return self.none_rms_m / self.offline_rms_m

    def row(self) -> list[Any]:
        return [self.scenario, self.seed, self.live_epochs, round(self.live_rms_m, 3),
                round(self.offline_rms_m, 3), round(self.ratio, 3), round(self.none_rms_m, 2),
                round(self.factor_live, 1), round(self.factor_offline, 1)]


COMPARISON_HEADER = ["scenario", "seed", "live epochs", "live RMS m", "sim insgnss RMS m",
                     "live / sim", "none RMS m", "none / live", "none / sim"]


def compare(setup: InsGnssSetup, scenario: Scenario, seed: int, out_dir: Path, *,
            speed: float = 50.0, imu_message: str = "HIGHRES_IMU",
            impair: LinkImpairment | None = None, mavlink_url: str = "",
            outage: tuple[float, float] | None = None,
            attitude_error_deg: float | None = None) -> Comparison:
    """Generate the scenario, run ``sim insgnss``'s filter (the preset's strategy) and "none"
    offline, play the same data to the live vehicle over ptys; see :class:`Comparison`.
    ``outage``: a GNSS outage of the live run only (:func:`build_events`; see
    :func:`coast_report`); ``attitude_error_deg``: the autopilot also sends ATTITUDE."""
    data = generate(setup, scenario, seed)
    strategy = setup.filter.strategy
    runs: dict[str, MethodRun] = {s: run_method(data, setup.filter, s)
                                  for s in (strategy, "none")}
    summary = summarize(data, runs, scenario, seed, setup)
    lr = run_live(setup, data, out_dir, imu_message=imu_message, impair=impair, seed=seed,
                  speed=speed, mavlink_url=mavlink_url, outage=outage,
                  attitude_error_deg=attitude_error_deg)
    if outage is not None:
        lr.coast = coast_report(lr.records, data, setup.filter.latitude_deg,
                                setup.sim.imu_rate_hz)
    return Comparison(scenario, seed, rms(lr.pos_err),
                      summary["methods"][strategy]["position_rms_3d_m"],
                      summary["methods"]["none"]["position_rms_3d_m"], len(lr.pos_err),
                      len(runs[strategy].pos_err), lr)
