"""``fdi-bridge soak --minutes 60``: the rover (10 Hz) and the ROV (5 Hz) together, accelerated.

Everything runs in one process on one :class:`~firmware_host.runtime.loop.FakeClock`, so a simulated
hour takes a minute or so of real time, and the result is the same on every run for a seed
(wall-clock values: the processing times and the memory). What runs is the bridge's own code —
the vehicles ``fdi-bridge run`` runs (:class:`~firmware_host.rover.vehicle.RoverVehicle`:
pipeline, MAVLink output, failsafe; :class:`~firmware_host.rov.vehicle.OutlandRovVehicle`:
:class:`~firmware_host.rov.control.RovController` on an :class:`~drivers.outland.link.OutlandLink`),
each on the runtime's :class:`~firmware_host.runtime.runner.Runner` (resilient ports, the
:class:`~firmware_host.runtime.recorder.FlightRecorder` on every port direction), stepped by
hand on one fake clock. Only the devices are
simulated (:class:`SimDevice`): the rover's receiver
(:func:`firmware_host.devtools.rover_sim.generate`,
GPS faults included) and the ROV (:class:`~firmware_host.devtools.rov_sim.RovSimServer`, compass
faults).

Injected: line noise (bit flips and bursts of garbage, seeded), port drops (the device is
unplugged: reads fail, the path is gone until it is plugged back), GPS and compass faults.

Measured and checked:

* overruns attributable to the bridge: a rover step that took longer (real time) than the
  receiver's 100 ms period, a ROV step longer than its 200 ms period;
* memory growth: RSS (``/proc/self/statm``) at the end minus after the first tenth of the run;
* counters: per device, bytes generated = bytes the bridge read + bytes lost while unplugged +
  bytes still waiting; per port direction, bytes read/written = bytes recorded; the rover's
  NMEA input counter = bytes read.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from drivers.capture import Channel
from drivers.outland.framecodec import load_protocol
from drivers.transport import SerialSettings
from fdi.errors import PortError
from firmware_host.commands.checks import output_dir_arg, output_file_arg, positive_float
from firmware_host.commands.tables import fields, fmt, table
from firmware_host.devtools.progress import Progress
from firmware_host.devtools.rov_sim import RovPlant, RovSimServer, parse_fault
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.rov.config import load_rov_config, protocol_path
from firmware_host.rov.vehicle import OutlandRovVehicle
from firmware_host.rover.vehicle import RoverVehicle
from firmware_host.runtime.config import BridgeConfig, RoverConfig
from firmware_host.runtime.loop import FakeClock
from firmware_host.runtime.mavout import packer_output
from firmware_host.runtime.recorder import FlightRecorder, RecorderConfig
from firmware_host.runtime.runner import Runner

GPS_URL = "sim://gps"
ROV_URL = "sim://rov"


def rss_bytes() -> int:
    """Resident set size of this process (Linux), 0 where unknown."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


@dataclass
class SimDevice:
    """The far end of a simulated serial line: bytes produced on the fake clock, plug state.

    ``produce(t0, t1)`` returns the bytes the device sends in ``(t0, t1]``; ``consume(data)``
    takes what the bridge writes and returns bytes to send at once (a polled reply).
    ``unplugged`` is a list of ``(start_s, end_s)``: the device is absent (open fails, an open
    port fails) in ``[start, end)``. Noise: each chunk has a bit flipped with probability
    ``flip_p`` and a burst of random bytes inserted with probability ``garbage_p``.
    """

    name: str
    clock: FakeClock
    produce: Callable[[float], bytes]
    consume: Callable[[bytes], bytes] = lambda data: b""
    unplugged: list[tuple[float, float]] = field(default_factory=list)
    flip_p: float = 0.0
    garbage_p: float = 0.0
    seed: int = 0
    generation: int = 0
    out: bytearray = field(default_factory=bytearray)
    generated: int = 0
    lost: int = 0
    received: int = 0
    rejected_writes: int = 0
    noise_events: Counter[str] = field(default_factory=Counter)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        self._was_plugged = True

    def plugged(self) -> bool:
        t = self.clock()
        return not any(a <= t < b for a, b in self.unplugged)

    def pump(self) -> None:
        """Bring the device up to the clock's time."""
        plugged = self.plugged()
        if not plugged and self._was_plugged:  # unplugged: what was in flight is lost
            self.lost += len(self.out)
            self.out.clear()
            self.generation += 1
        self._was_plugged = plugged
        data = self._noisy(self.produce(self.clock()))
        if not data:
            return
        self.generated += len(data)
        if plugged:
            self.out += data
        else:
            self.lost += len(data)

    def _noisy(self, data: bytes) -> bytes:
        if not data:
            return data
        if self.flip_p and self.rng.random() < self.flip_p:
            b = bytearray(data)
            i = int(self.rng.integers(len(b)))
            b[i] ^= 1 << int(self.rng.integers(8))
            data = bytes(b)
            self.noise_events["bit_flip"] += 1
        if self.garbage_p and self.rng.random() < self.garbage_p:
            i = int(self.rng.integers(len(data) + 1))
            junk = self.rng.integers(0, 256, int(self.rng.integers(1, 40)), dtype=np.uint8)
            data = data[:i] + junk.tobytes() + data[i:]
            self.noise_events["garbage"] += 1
        return data


class SimPort:
    """What the bridge's opener returns for a :class:`SimDevice` (non-blocking reads)."""

    def __init__(self, dev: SimDevice) -> None:
        self.dev = dev
        self.generation = dev.generation
        self.port = dev.name

    def _check(self) -> None:
        self.dev.pump()
        if self.dev.generation != self.generation or not self.dev.plugged():
            raise OSError(5, "Input/output error")  # what a vanished USB adapter gives

    @property
    def in_waiting(self) -> int:
        self._check()
        return len(self.dev.out)

    def read(self, size: int = 1) -> bytes:
        self._check()
        data = bytes(self.dev.out[:size])
        del self.dev.out[:size]
        return data

    def write(self, data: bytes) -> int:
        self._check()
        self.dev.received += len(data)
        reply = self.dev.consume(bytes(data))
        if reply:
            self.dev.out += reply
        return len(data)

    def reset_input_buffer(self) -> None:
        self._check()

    def close(self) -> None:
        pass


def sim_opener(devices: dict[str, SimDevice]) -> Callable[[SerialSettings], SimPort]:
    def opener(settings: SerialSettings) -> SimPort:
        dev = devices[settings.url]
        dev.pump()
        if not dev.plugged():
            raise PortError(f"could not open {settings.url!r}: [Errno 2] No such file")
        return SimPort(dev)

    return opener


def gps_producer(sc: RoverScenario) -> Callable[[float], bytes]:
    """Epoch k of the scenario is sent at ``k / rate`` seconds."""
    it: Iterator[tuple[float, bytes, dict[str, object]]] = generate(sc)
    state = {"k": 0, "done": False}
    period = 1.0 / sc.rate_hz

    def produce(now: float) -> bytes:
        out = b""
        while not state["done"] and state["k"] * period <= now + 1e-9:
            try:
                _, data, _ = next(it)
            except StopIteration:
                state["done"] = True
                break
            out += data
            state["k"] += 1
        return out

    return produce


def rov_device(server: RovSimServer, clock: FakeClock, **kw: Any) -> SimDevice:
    """The ROV streaming telemetry (RS-232) every period, commands consumed."""
    state = {"next": server.period_s}

    def produce(now: float) -> bytes:
        out = b""
        while state["next"] <= now + 1e-9:
            out += server.tick()
            state["next"] += server.period_s
        return out

    return SimDevice("rov", clock, produce, server.receive, **kw)


def _plan_unplugs(rng: np.random.Generator, duration_s: float, n: int,
                  lo_s: float, hi_s: float) -> list[tuple[float, float]]:
    out = []
    for k in range(n):
        start = duration_s * (k + 0.5 + 0.3 * float(rng.uniform(-1, 1))) / (n + 0.5)
        out.append((round(start, 1), round(start + float(rng.uniform(lo_s, hi_s)), 1)))
    return out


def run_soak(
    minutes: float,
    *,
    seed: int = 1,
    record_dir: Path | None = None,
    gps_drops: int | None = None,
    rov_drops: int | None = None,
    flip_p: float = 0.01,
    garbage_p: float = 0.005,
    progress: Callable[[float], None] | None = None,
    background_sync: bool = True,
    stop: Callable[[], bool] | None = None,
) -> dict[str, Any]:
    """Run the soak for ``minutes`` simulated minutes; return the figures (see module doc).
    ``stop()`` true (checked between steps, e.g. after a ^C): end there, with the figures of
    what ran, ``partial`` and not ``ok``."""
    duration = minutes * 60.0
    clock = FakeClock(0.0)
    rng = np.random.default_rng(seed)
    wall_us0 = 1_700_000_000_000_000

    def wall_us() -> int:  # recorder timestamps follow the fake clock
        return wall_us0 + round(clock() * 1e6)

    n_gps = gps_drops if gps_drops is not None else max(1, round(minutes / 10))
    n_rov = rov_drops if rov_drops is not None else max(1, round(minutes / 15))
    # The receiver: a generated rover run with GPS faults, 10 Hz.
    sc = RoverScenario(rate_hz=10.0, duration_s=duration + 1.0, seed=seed)
    gps = SimDevice("gps", clock, gps_producer(sc), flip_p=flip_p, garbage_p=garbage_p,
                    seed=seed + 1, unplugged=_plan_unplugs(rng, duration, n_gps, 1.0, 20.0))
    # The ROV: streaming telemetry at 5 Hz with compass faults.
    rcfg, base = load_rov_config(None)
    proto = load_protocol(protocol_path(rcfg, base))
    spans = [0.15, 0.35, 0.55, 0.75]
    faults = [parse_fault(f"drift:20@{duration * spans[0]:.0f}-{duration * spans[0] + 120:.0f}"),
              parse_fault(f"stuck@{duration * spans[1]:.0f}-{duration * spans[1] + 60:.0f}"),
              parse_fault(f"spike:25@{duration * spans[2]:.0f}-{duration * spans[2] + 0.4:.1f}"),
              parse_fault(f"dropout@{duration * spans[3]:.0f}-{duration * spans[3] + 5:.0f}")]
    plant = RovPlant(rcfg.sim, faults)
    server = RovSimServer(plant, proto, "rs232", node=rcfg.link.address, period_s=rcfg.period_s)
    rov = rov_device(server, clock, flip_p=flip_p, garbage_p=garbage_p, seed=seed + 2,
                     unplugged=_plan_unplugs(rng, duration, n_rov, 1.0, 10.0))
    opener = sim_opener({GPS_URL: gps, ROV_URL: rov})

    tmp = None
    if record_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="fdi-soak-")
        record_dir = Path(tmp.name)
    rec_cfg = RecorderConfig(dir=str(record_dir), file_max_mb=2.0, dir_max_mb=8.0)
    recorder = FlightRecorder(record_dir, rec_cfg, note="fdi-bridge soak", clock=clock,
                              wall_us=wall_us, background_sync=background_sync)

    # The rover and the ROV: the vehicles `fdi-bridge run` runs, each on the runtime's Runner
    # (resilient, recorded ports; the rover's failsafe; the MAVLink output encoded, recorded,
    # sent nowhere), both driven step by step on the one fake clock.
    mav_tap = recorder.tap(recorder.add_channel(Channel("mavlink tx", "packer", direction="tx")))
    rover_cfg = BridgeConfig(rover=replace(RoverConfig(), port=SerialSettings(url=GPS_URL),
                                           reconnect_max_s=2.0))
    devnull = open(os.devnull, "w", encoding="utf-8")  # noqa: SIM115 - closed below
    rover_v = RoverVehicle(rover_cfg)
    rover = Runner(rover_v, jsonl=devnull, recorder=recorder, own_recorder=False,
                   mavlink_output=packer_output(tap=mav_tap, clock=clock), clock=clock,
                   opener=opener, handle_signals=False)
    rcfg = replace(rcfg, link=replace(rcfg.link, port=SerialSettings(url=ROV_URL, timeout_s=0.0),
                                      wiring="rs232", reconnect_max_s=2.0))
    rov_v = OutlandRovVehicle(rcfg, base)
    rov_runner = Runner(rov_v, recorder=recorder, own_recorder=False, clock=clock,
                        opener=opener, handle_signals=False)

    perf = time.perf_counter
    rover_period, rov_period = 0.1, rcfg.period_s
    rover_over = rov_over = 0
    rover_worst = rov_worst = 0.0
    rss0 = rss_bytes()
    rss_warm: int | None = None
    k = 0
    steps = round(duration / rover_period)
    rov_every = round(rov_period / rover_period)
    interrupted = False
    try:
        rover.start()
        rov_runner.start()
        while k < steps:
            if stop is not None and stop():
                interrupted = True
                break
            clock.now = k * rover_period  # absolute deadlines: next = k * period
            gps.pump()  # the devices' own work (simulation) is not timed as the bridge's
            rov.pump()
            t0 = perf()
            rover.step()
            dt = perf() - t0
            rover_worst = max(rover_worst, dt)
            rover_over += dt > rover_period
            if k % rov_every == 0:
                t0 = perf()
                rov_runner.step(clock())
                dt = perf() - t0
                rov_worst = max(rov_worst, dt)
                rov_over += dt > rov_period
            k += 1
            if rss_warm is None and k >= steps // 10:
                rss_warm = rss_bytes()
            if progress is not None and k % 6000 == 0:
                progress(clock())
        if not interrupted:
            clock.now = steps * rover_period
            rover.step()
    finally:
        summ = rover.close()
        rov_summ = rov_runner.close()
        recorder.close()
        devnull.close()
    gps_port, rov_port = rover.ports["gps"], rov_runner.ports["rov link"]
    rss_end = rss_bytes()
    by_ch = recorder.counters()["bytes_by_channel"]
    assert isinstance(by_ch, dict)
    gps_pending = len(gps.out)
    rov_pending = len(rov.out)
    checks = {
        "gps: generated = read + lost + pending":
            gps.generated == gps_port.bytes_rx + gps.lost + gps_pending,
        "gps: read = recorded": gps_port.bytes_rx == by_ch["gps rx"],
        "gps: read = NMEA bytes_in": gps_port.bytes_rx == summ["input"]["bytes_in"],
        "rov: generated = read + lost + pending":
            rov.generated == rov_port.bytes_rx + rov.lost + rov_pending,
        "rov: read = recorded": rov_port.bytes_rx == by_ch["rov link rx"],
        "rov: written = received by the vehicle = recorded":
            rov_port.bytes_tx == rov.received == by_ch["rov link tx"],
        "recorder: no write errors": recorder.write_errors == 0,
    }
    result: dict[str, Any] = {
        "simulated_s": round(k * rover_period, 1) if interrupted else duration,
        "seed": seed,
        "rover": {
            "epochs": summ["epochs"], "faults": summ["faults"], "alarms": summ["alarms"],
            "actions": summ["actions"], "input": summ["input"], "port": summ["port"],
            "failsafe": summ["failsafe"], "overruns": rover_over,
            "worst_step_ms": round(rover_worst * 1e3, 3),
            "unplugged": gps.unplugged, "noise": dict(gps.noise_events),
            "bytes_generated": gps.generated, "bytes_lost_unplugged": gps.lost,
        },
        "rov": {
            "steps": sum(rov_summ["actions"].values()), "actions": rov_summ["actions"],
            "link": rov_summ["counts"], "rejects": rov_summ["rejects"],
            "port": rov_port.counters(), "failsafe_episodes": rov_summ["failsafe"]["episodes"],
            "neutral_episodes": rov_summ["failsafe"]["neutral"], "overruns": rov_over,
            "worst_step_ms": round(rov_worst * 1e3, 3), "unplugged": rov.unplugged,
            "noise": dict(rov.noise_events), "bytes_generated": rov.generated,
            "bytes_lost_unplugged": rov.lost,
            "faults": [f"{f.kind}@{f.start_s:g}-{f.end_s:g}" for f in faults],
        },
        "recorder": recorder.counters(),
        "memory": {
            "rss_start_mb": round(rss0 / 1e6, 2),
            "rss_after_warmup_mb": round((rss_warm or rss0) / 1e6, 2),
            "rss_end_mb": round(rss_end / 1e6, 2),
            "growth_mb": round((rss_end - (rss_warm or rss0)) / 1e6, 2),
        },
        "checks": checks,
        "ok": all(checks.values()) and rover_over == 0 and rov_over == 0
        and (rss_end - (rss_warm or rss0)) < 10e6,
    }
    if interrupted:  # what ran is checked and reported; a partial soak is not a pass
        result["partial"] = True
        result["ok"] = False
    if tmp is not None:
        tmp.cleanup()
    if not math.isfinite(result["memory"]["growth_mb"]):
        result["ok"] = False
    return result


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--minutes", type=positive_float, default=60.0,
                        help="simulated minutes")
    parser.add_argument("--seed", type=int, default=1, help="random seed of faults and drops")
    parser.add_argument("--record-dir", type=output_dir_arg, default=None,
                        help="keep the flight recordings here (default: a temporary directory)")
    parser.add_argument("--out", type=output_file_arg, default=None,
                        help="write the figures as JSON to this file")
    parser.add_argument("--json", action="store_true",
                        help="print the figures as JSON (default: tables)")


def _counts(d: Any) -> str:
    if not isinstance(d, dict) or not d:
        return "-"
    return ", ".join(f"{k} {fmt(v)}" for k, v in d.items())


def _spans(spans: Any) -> str:
    return ", ".join(f"{fmt(a)}-{fmt(b)} s" for a, b in spans) if spans else "-"


def soak_text(r: dict[str, Any]) -> str:
    """The soak's figures for a human: the verdict, one column a vehicle, the recorder, the
    memory and the byte-accounting checks."""
    ro, rv = r["rover"], r["rov"]
    rp, vp = ro["port"], rv["port"]
    verdict = "PARTIAL (interrupted)" if r.get("partial") else "ok" if r["ok"] else "FAILED"
    head = (f"soak: {fmt(r['simulated_s'] / 60)} min simulated in {fmt(r.get('real_s'))} s, "
            f"seed {r['seed']}: {verdict}")
    rows: list[list[Any]] = [
        ["epochs / steps", ro["epochs"], rv["steps"], ""],
        ["faults", ro["faults"], len(rv["faults"]), "rover: epochs flagged; rov: injected"],
        ["alarms", ro["alarms"], None, ""],
        ["actions", _counts(ro["actions"]), _counts(rv["actions"]), ""],
        ["bytes generated", ro["bytes_generated"], rv["bytes_generated"], ""],
        ["bytes read", rp["bytes_rx"], vp["bytes_rx"], ""],
        ["bytes lost unplugged", ro["bytes_lost_unplugged"], rv["bytes_lost_unplugged"], ""],
        ["unplugged", _spans(ro["unplugged"]), _spans(rv["unplugged"]), ""],
        ["port losses / reopens", f"{rp['losses']} / {rp['reopens']}",
         f"{vp['losses']} / {vp['reopens']}", ""],
        ["noise injected", _counts(ro["noise"]), _counts(rv["noise"]), ""],
        ["input rejected", ro["input"].get("rejected_total"),
         sum(rv["rejects"].values()), "lines / frames"],
        ["failsafe", _counts(ro["failsafe"]),
         f"episodes {rv['failsafe_episodes']}, neutral {rv['neutral_episodes']}", ""],
        ["overruns", ro["overruns"], rv["overruns"], ""],
        ["worst step", ro["worst_step_ms"], rv["worst_step_ms"], "ms"],
    ]
    rec, mem = r["recorder"], r["memory"]
    recorder = fields([
        ("recorder records", rec.get("records"), f"in {fmt(rec.get('files_opened'))} files"),
        ("write errors", rec.get("write_errors"), ""),
        ("lost bytes", rec.get("lost_bytes"), ""),
        ("max flush", rec.get("max_flush_ms"), "ms"),
        ("memory", mem["rss_end_mb"], f"MB at the end ({fmt(mem['growth_mb'])} MB growth "
                                      "after warm-up, limit 10)"),
    ])
    checks = table(["check", "result"],
                   [[name, "pass" if ok else "FAIL"] for name, ok in r["checks"].items()])
    return "\n\n".join([head, table(["", "rover", "rov", "unit"], rows), recorder, checks])


def run(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    with Progress(max(1, round(args.minutes)), "soak", unit="min") as bar:
        done = [0]

        def progress(t: float) -> None:
            minute = int(t // 60)
            bar.step(n=max(0, minute - done[0]))
            done[0] = max(done[0], minute)

        # ^C: the soak stops between two steps and reports what ran (partial), exit 130.
        interrupted = threading.Event()
        previous = signal.signal(signal.SIGINT, lambda signum, frame: interrupted.set())
        try:
            result = run_soak(args.minutes, seed=args.seed, record_dir=args.record_dir,
                              progress=progress, stop=interrupted.is_set)
        finally:
            signal.signal(signal.SIGINT, previous)
    result["real_s"] = round(time.perf_counter() - t0, 1)
    text = json.dumps(result, indent=2)
    print(text if args.json else soak_text(result))
    if args.out is not None:
        args.out.write_text(text + "\n")
    if result.get("partial"):
        print(f"soak interrupted at {result['simulated_s']:g} s simulated: partial figures",
              file=sys.stderr)
        return 130
    return 0 if result["ok"] else 1
