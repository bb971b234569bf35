"""``fdi-bridge bench``: the project's benchmark command (prints a table, writes JSON).

Speed is measured here, never asserted in tests. Figures (goals from issue 6 in the table):

* per-epoch processing time (p50/p99/max, ms) of the rover pipeline per strategy (grey,
  three_zone, combined; detector, conversion and record, no outputs), of one ROV step
  (detector + substitution + PID) and of the INS/GNSS step (one 100 Hz IMU propagation; the
  1 Hz GNSS update apart);
* offline replay throughput (epochs/s, parse included) without a pty and through a real pty;
* end-to-end latency: from the last byte of a GGA written into the receiver's pty to the
  GPS_INPUT it causes arriving on a UDP socket (the pipeline reads the pty in its own thread,
  as ``fdi-bridge run`` does; each epoch is sent RMC, VTG, then GGA so that GGA ends the burst);
* the fixed-rate loop (:class:`firmware_host.runtime.loop.FixedRateLoop`) at 5 Hz and 10 Hz for
  ``--duration`` seconds with real ptys on both ends: a feeder writes one receiver epoch per
  period into the input pty, each step reads it, runs the pipeline and writes corrected NMEA
  into an output pty that a drain thread empties; start jitter p50/p99/max and overruns;
* MAVLink forwarding latency (:func:`firmware_host.devtools.router_bench.bench_forwarding`), added
by the
  router over a direct UDP path.

* replay's peak memory (max RSS of a child ``fdi-bridge replay``) on a 24 h and a 1 min log at
  1 Hz, plain NMEA and capture (:func:`bench_replay_memory`; alone: ``--only replay-memory``).

With the defaults it runs in about four minutes (the two 60 s loops and the 24 h replays
dominate).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from drivers.mavlink.io import MavEndpoint
from drivers.ptypair import PtyPair
from drivers.transport import SerialSettings, open_port, read_some
from firmware_host.commands.replay import (
    ReplayInput,
    load_input,
    replay_direct,
    replay_through_pty,
)
from firmware_host.devtools.insgnss_sim import bench_insgnss_step
from firmware_host.devtools.rover_sim import RoverScenario, generate, write_run
from firmware_host.rov.app import bench_rov_step
from firmware_host.rover.outputs import MavlinkGpsSink, NmeaSink, gps_week_ms, unix_time
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.runtime.config import BridgeConfig
from firmware_host.runtime.loop import FixedRateLoop

STRATEGIES = ("grey", "three_zone", "combined")


def _pct(values_s: list[float] | np.ndarray) -> dict[str, float]:
    arr = np.asarray(values_s, dtype=float) * 1e3
    if arr.size == 0:
        return {"n": 0, "p50": float("nan"), "p99": float("nan"), "max": float("nan")}
    return {"n": int(arr.size), "p50": float(np.percentile(arr, 50)),
            "p99": float(np.percentile(arr, 99)), "max": float(arr.max())}


def _cfg(strategy: str | None = None) -> BridgeConfig:
    cfg = BridgeConfig()
    if strategy is None:
        return cfg
    det = replace(cfg.rover.detector, strategy=strategy)  # type: ignore[arg-type]
    return replace(cfg, rover=replace(cfg.rover, detector=det))


def bench_rover(duration_s: float = 600.0, rate_hz: float = 10.0) -> dict[str, Any]:
    """Per-epoch time per strategy and replay throughput, on a generated run."""
    tmp = Path(tempfile.mkdtemp(prefix="fdi-bench-"))
    write_run(RoverScenario(rate_hz=rate_hz, duration_s=duration_s, seed=7), tmp)
    inp = ReplayInput(list(load_input(tmp / "rover.nmea").chunks))  # in memory: pipeline alone
    out: dict[str, Any] = {"epochs": int(duration_s * rate_hz), "rate_hz": rate_hz}
    per: dict[str, Any] = {}
    for strat in STRATEGIES:
        cfg = _cfg(strat)
        best = 0.0
        proc: list[float] = []
        for _ in range(3):  # throughput: no pty, no JSON output: parse + detect
            pipe = RoverPipeline(cfg.rover)
            t0 = time.perf_counter()
            replay_direct(inp, pipe)
            best = max(best, pipe.epochs / (time.perf_counter() - t0))
            proc = list(pipe.timer.stats.proc_s)
        per[strat] = {"epoch_ms": _pct(proc), "throughput_eps_no_pty": best}
    out["strategies"] = per
    cfg = _cfg()
    out["default_strategy"] = cfg.rover.detector.strategy
    out["epoch_ms"] = per[cfg.rover.detector.strategy]["epoch_ms"]
    out["throughput_eps_no_pty"] = per[cfg.rover.detector.strategy]["throughput_eps_no_pty"]
    pipe = RoverPipeline(cfg.rover, jsonl=io.StringIO())
    t0 = time.perf_counter()
    replay_direct(inp, pipe)
    out["throughput_eps_no_pty_jsonl"] = pipe.epochs / (time.perf_counter() - t0)
    pipe = RoverPipeline(cfg.rover)
    t0 = time.perf_counter()
    replay_through_pty(inp, pipe)
    out["throughput_eps_pty"] = pipe.epochs / (time.perf_counter() - t0)
    pipe = RoverPipeline(cfg.rover, jsonl=io.StringIO())
    t0 = time.perf_counter()
    replay_through_pty(inp, pipe)
    out["throughput_eps_pty_jsonl"] = pipe.epochs / (time.perf_counter() - t0)
    return out


def _epochs_gga_last(n: int, rate_hz: float) -> list[tuple[bytes, bytes, int]]:
    """``n`` generated epochs as (RMC + VTG, GGA, GPS milliseconds of week), GGA last."""

    sc = RoverScenario(rate_hz=rate_hz, duration_s=n / rate_hz + 1.0, seed=3, kinds=("jump",),
                       fault_every_s=1e9)
    out = []
    for _, data, truth in generate(sc):
        lines = data.splitlines(keepends=True)
        gga = b"".join(x for x in lines if x[3:6] == b"GGA")
        rest = b"".join(x for x in lines if x[3:6] != b"GGA")
        utc = float(truth["utc"])  # type: ignore[arg-type]
        out.append((rest, gga, gps_week_ms(unix_time(sc.date, utc))[1]))
        if len(out) == n:
            break
    return out


class _PortReader(threading.Thread):
    """Reads a port and feeds the pipeline until stopped (what ``fdi-bridge run`` does)."""

    def __init__(self, port: Any, pipe: RoverPipeline) -> None:
        super().__init__(name="bench-reader", daemon=True)
        self.port, self.pipe = port, pipe
        self.stop = threading.Event()
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            while not self.stop.is_set():
                data = read_some(self.port, 65536)
                if data:
                    self.pipe.feed(data)
        except BaseException as err:  # reported by the caller
            self.error = err


def bench_end_to_end(epochs: int = 200, rate_hz: float = 10.0, warmup: int = 20
                     ) -> dict[str, Any]:
    """Last byte of a GGA into the receiver pty -> GPS_INPUT on a UDP socket (ms)."""

    rx = MavEndpoint("udpin:127.0.0.1:0")
    addr = rx.local_address
    assert addr is not None
    cfg = BridgeConfig()
    rover = replace(cfg.rover, output=replace(cfg.rover.output,
                                              mavlink_url=f"udpout:127.0.0.1:{addr[1]}"))
    lat: list[float] = []
    lost = 0
    with PtyPair(baudrate=115200) as pty:
        port = open_port(SerialSettings(url=pty.url, baudrate=115200, timeout_s=0.05))
        pipe = RoverPipeline(rover, sinks=[MavlinkGpsSink(rover)])
        reader = _PortReader(port, pipe)
        reader.start()
        period = 1.0 / rate_hz
        try:
            next_t = time.perf_counter()
            for k, (head, gga, week_ms) in enumerate(_epochs_gga_last(epochs + warmup,
                                                                      rate_hz)):
                pty.write(head)
                pty.write(gga)
                t0 = time.perf_counter()
                got = None
                while got is None:  # this epoch's GPS_INPUT (by its time), not a late one
                    msg = rx.recv(timeout_s=0.5)
                    if msg is None:
                        break
                    if msg.get_type() == "GPS_INPUT" and abs(msg.time_week_ms - week_ms) <= 1:
                        got = time.perf_counter()
                if got is None:
                    lost += k >= warmup
                elif k >= warmup:
                    lat.append(got - t0)
                next_t += period
                delay = next_t - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
        finally:
            reader.stop.set()
            reader.join(timeout=2.0)
            port.close()
            pipe.finish()
            rx.close()
    if reader.error is not None:
        raise RuntimeError(f"bench reader failed: {reader.error}") from reader.error
    return {"rate_hz": rate_hz, "lost": lost, "latency_ms": _pct(lat)}


def bench_loop(rate_hz: float, duration_s: float) -> dict[str, Any]:
    """The fixed-rate loop at ``rate_hz`` with real ptys on both ends (see the module doc)."""

    period = 1.0 / rate_hz
    n = max(1, round(duration_s * rate_hz))
    stop = threading.Event()
    with PtyPair(baudrate=115200) as pin:
        out_link = Path(tempfile.mkdtemp(prefix="fdi-bench-")) / "gps-out"
        sink = NmeaSink(f"pty:{out_link}", 115200)
        out_pty = sink.writer.pty
        assert out_pty is not None
        port = open_port(SerialSettings(url=pin.url, baudrate=115200, timeout_s=0.0))
        pipe = RoverPipeline(BridgeConfig().rover, sinks=[sink])
        epochs = [h + g for h, g, _ in _epochs_gga_last(n + 1, rate_hz)]

        def feed() -> None:  # the receiver: one epoch per period, on its own deadlines
            t = time.perf_counter()
            for data in epochs:
                if stop.is_set():
                    return
                pin.write(data)
                t += period
                d = t - time.perf_counter()
                if d > 0:
                    time.sleep(d)

        # The autosteer unit: opens the output pty's slave by its path and reads it.
        out_fd = os.open(out_pty.slave_path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)

        def drain() -> None:
            import select

            while not stop.is_set():
                ready, _, _ = select.select([out_fd], [], [], 0.05)
                if ready:
                    with contextlib.suppress(BlockingIOError):
                        os.read(out_fd, 65536)

        threads = [threading.Thread(target=f, daemon=True) for f in (feed, drain)]
        for t in threads:
            t.start()

        def step(k: int, t: float) -> bool:
            data = read_some(port, 65536)
            if data:
                pipe.feed(data)
            return True

        loop = FixedRateLoop(period)
        try:
            stats = loop.run(step, max_steps=n)
        finally:
            stop.set()
            for t in threads:
                t.join(timeout=2.0)
            port.close()
            sink.close()
            os.close(out_fd)
    s = stats.summary()
    return {"rate_hz": rate_hz, "duration_s": duration_s, "steps": s["steps"],
            "overruns": s["overruns"], "epochs": pipe.epochs,
            "jitter_ms": {"p50": s.get("jitter_p50_ms"), "p99": s.get("jitter_p99_ms"),
                          "max": s.get("jitter_max_ms")},
            "step_ms": {"p50": s.get("proc_p50_ms"), "p99": s.get("proc_p99_ms"),
                        "max": s.get("proc_max_ms")}}


def bench_forwarding_figures(rate_pps: int = 200, seconds: float = 5.0) -> dict[str, Any]:
    """:func:`firmware_host.devtools.router_bench.bench_forwarding` in a child interpreter, with a
    deadline: it spawns its own sender/receiver processes, which need an importable main
    module, and a failing child must not hang this command."""
    import subprocess
    import sys

    code = ("import json, sys\n"
            "from firmware_host.devtools.router_bench import bench_forwarding\n"
            "if __name__ == '__main__':\n"
            f"    print(json.dumps(bench_forwarding({int(rate_pps)}, {float(seconds)!r})))\n")
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=4 * seconds + 60.0, check=False)
    except subprocess.TimeoutExpired:
        return {"error": "timed out"}
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or ["?"])[-1]
        return {"error": f"failed: {tail}"}
    return dict(json.loads(proc.stdout.strip().splitlines()[-1]))


def bench_replay_memory(long_s: float = 86400.0, short_s: float = 60.0, rate_hz: float = 1.0,
                        kinds: tuple[str, ...] = ("rover.nmea", "rover.cap")) -> dict[str, Any]:
    """Peak memory (max RSS, MiB) of ``fdi-bridge replay`` on a 24 h and on a 1 min log.

    Each replay runs in its own child process (through a pty, JSON Lines written, as a user
    runs it); its peak RSS comes from ``wait4``. Replay streams its input, so the long log's
    peak should be within 10 % of the short one's (issue 18: 118 MiB when it held every line).
    """
    tmp = Path(tempfile.mkdtemp(prefix="fdi-bench-mem-"))
    out: dict[str, Any] = {"rate_hz": rate_hz, "long_s": long_s, "short_s": short_s}
    for name, dur in (("short", short_s), ("long", long_s)):
        write_run(RoverScenario(rate_hz=rate_hz, duration_s=dur, seed=7), tmp / name)
    for kind in kinds:
        peaks = {}
        for name in ("short", "long"):
            proc = subprocess.Popen(
                [sys.executable, "-m", "firmware_host.cli", "replay", str(tmp / name / kind),
                 "--out", str(tmp / f"out-{name}")],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            _, status, usage = os.wait4(proc.pid, 0)
            proc.returncode = os.waitstatus_to_exitcode(status)
            if proc.returncode != 0:
                raise RuntimeError(f"replay of {kind} ({name}) exited {proc.returncode}")
            peaks[name] = usage.ru_maxrss / 1024.0  # KiB on Linux
        out[kind] = {"short_mib": round(peaks["short"], 1), "long_mib": round(peaks["long"], 1),
                     "ratio": round(peaks["long"] / peaks["short"], 3)}
    shutil.rmtree(tmp, ignore_errors=True)
    return out


def _machine() -> dict[str, Any]:
    model = ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            model = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")),
                         "")
    except OSError:
        pass
    return {"python": platform.python_version(), "cpu": model or platform.processor()
            or platform.machine(), "cores": os.cpu_count(), "system": platform.platform(),
            "numpy": np.__version__}


def run_bench(duration_s: float = 60.0, replay_s: float = 600.0, e2e_epochs: int = 200,
              fwd_seconds: float = 5.0, fwd_rate: int = 200) -> dict[str, Any]:
    t0 = time.perf_counter()
    res: dict[str, Any] = {"machine": _machine(), "rover": bench_rover(replay_s)}
    res["rov_step"] = bench_rov_step(5000)
    res["insgnss_step"] = bench_insgnss_step(10000)
    res["end_to_end"] = bench_end_to_end(e2e_epochs)
    res["loop"] = {f"{r:g}hz": bench_loop(r, duration_s) for r in (5.0, 10.0)}
    res["mavlink_forwarding"] = bench_forwarding_figures(fwd_rate, fwd_seconds)
    res["replay_memory"] = bench_replay_memory()
    res["seconds"] = round(time.perf_counter() - t0, 1)
    return res


def table(res: dict[str, Any]) -> str:
    def f(x: Any, nd: int = 3) -> str:
        return "–" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{x:.{nd}f}"

    r = res["rover"]
    rows = ["| figure | p50 | p99 | max | goal |", "|---|---|---|---|---|"]
    for strat, v in r["strategies"].items():
        e = v["epoch_ms"]
        rows.append(f"| rover per-epoch, {strat} (ms) | {f(e['p50'])} | {f(e['p99'])} "
                    f"| {f(e['max'])} | p99 < 0.5 |")
    rov, ins = res["rov_step"], res["insgnss_step"]
    rows.append(f"| ROV step (ms) | {f(rov['p50_ms'])} | {f(rov['p99_ms'])} "
                f"| {f(rov.get('max_ms'))} | |")
    rows.append(f"| INS/GNSS IMU step (ms) | {f(ins['p50_ms'])} | {f(ins['p99_ms'])} | – | |")
    if "update_p50_ms" in ins:
        rows.append(f"| INS/GNSS GNSS update (ms) | {f(ins['update_p50_ms'])} "
                    f"| {f(ins['update_p99_ms'])} | – | |")
    e2e = res["end_to_end"]["latency_ms"]
    rows.append(f"| GGA last byte into pty -> GPS_INPUT on UDP (ms) | {f(e2e['p50'])} "
                f"| {f(e2e['p99'])} | {f(e2e['max'])} | p99 < 2 |")
    for name, lp in res["loop"].items():
        j = lp["jitter_ms"]
        rows.append(f"| loop {name} jitter (ms), {lp['steps']} steps, {lp['overruns']} overruns "
                    f"| {f(j['p50'])} | {f(j['p99'])} | {f(j['max'])} | p99 < 2, no overruns |")
    fw = res["mavlink_forwarding"]
    if "p50_ms" in fw:
        rows.append(f"| MAVLink forwarding latency, {fw['rate_pps']} pkt/s (ms) | "
                    f"{f(fw['p50_ms'])} | {f(fw['p99_ms'])} | {f(fw['max_ms'])} | |")
        rows.append(f"| ... added by the router over direct UDP (ms) | {f(fw['added_p50_ms'])} "
                    f"| {f(fw['added_p99_ms'])} | – | |")
    rows.append("")
    rows.append("| throughput (epochs/s, parse included) | value | goal |")
    rows.append("|---|---|---|")
    for strat, v in r["strategies"].items():
        rows.append(f"| no pty, {strat} | {v['throughput_eps_no_pty']:.0f} | >= 20000 |")
    rows.append(f"| no pty, JSON Lines written | {r['throughput_eps_no_pty_jsonl']:.0f} | |")
    rows.append(f"| through a pty | {r['throughput_eps_pty']:.0f} | |")
    rows.append(f"| through a pty, JSON Lines written | {r['throughput_eps_pty_jsonl']:.0f} | |")
    rows += replay_memory_rows(res["replay_memory"])
    return "\n".join(rows)


def replay_memory_rows(mem: dict[str, Any]) -> list[str]:
    rows = ["", f"| replay peak RSS (MiB), {mem['rate_hz']:g} Hz | {mem['short_s'] / 60:g} min log "
            f"| {mem['long_s'] / 3600:g} h log | ratio | goal |", "|---|---|---|---|---|"]
    for kind, v in mem.items():
        if isinstance(v, dict):
            rows.append(f"| {kind} | {v['short_mib']:.1f} | {v['long_mib']:.1f} "
                        f"| {v['ratio']:.3f} | <= 1.10 |")
    return rows


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--duration", type=float, default=60.0,
                        help="seconds of each fixed-rate loop run, 5 Hz and 10 Hz (default 60)")
    parser.add_argument("--replay-duration", type=float, default=600.0,
                        help="simulated seconds of rover data for timing/throughput (default 600)")
    parser.add_argument("--e2e-epochs", type=int, default=200,
                        help="epochs for the end-to-end latency (default 200, at 10 Hz)")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    parser.add_argument("--only", choices=("replay-memory",), default=None,
                        help="measure just this figure (replay-memory: about a minute)")


def run(args: argparse.Namespace) -> int:
    import logging

    logging.getLogger("fdi_bridge.rover").setLevel(logging.ERROR)  # gate-health notes etc.
    if args.only == "replay-memory":
        mem = bench_replay_memory()
        print("\n".join(replay_memory_rows(mem)[1:]))
        if args.json is not None:
            args.json.write_text(json.dumps({"replay_memory": mem}, indent=2) + "\n")
        return 0
    res = run_bench(args.duration, args.replay_duration, args.e2e_epochs)
    m = res["machine"]
    print(f"machine: {m['cpu']}, {m['cores']} cores, Python {m['python']}, {m['system']}")
    print(table(res))
    print(f"({res['seconds']} s)")
    out = args.json or Path(tempfile.gettempdir()) / "fdi-bridge-bench.json"
    out.write_text(json.dumps(res, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {out}")
    return 0
