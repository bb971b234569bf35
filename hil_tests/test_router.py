"""The MAVLink router over real loopback UDP: tlog replay byte for byte, params, signing."""

from __future__ import annotations

import contextlib
import os
import socket
import stat
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from drivers.mavlink import io as mio
from drivers.mavlink.framer import MavFramer, frame_target
from firmware_host.mavlink.params import ParamSpec, ParamStore
from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig, Router, load_signing_key

ROOT = Path(__file__).resolve().parents[1]
SMALL_TLOG = ROOT.parent / "shared" / "corpus" / "ardusub" / "small.tlog"
GCS_ID = (255, 190)


def _wait(cond: Callable[[], bool], what: str, deadline_s: float = 10.0) -> None:
    end = time.monotonic() + deadline_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0)  # yield to the router thread; the deadline bounds the wait


def _router(tmp_path: Path, **kw: object) -> tuple[Router, ParamStore]:
    params = ParamStore(tmp_path / "params.toml")
    params.register(ParamSpec("FDI_ALPHA", 0.05, 1e-6, 0.5, "false-alarm rate"))
    params.register(ParamSpec("FDI_WINDOW", 20.0, 1.0, 500.0, "window length, epochs"))
    cfg = MavlinkConfig(
        autopilot=EndpointConfig("udpin:127.0.0.1:0"),
        gcs=(EndpointConfig("udpin:127.0.0.1:0", signing=bool(kw.get("signing"))),),
        signing_key_file=str(kw.get("key_file", "")),
        queue_packets=4000,
        read_burst=256,
        tlog_dir=str(tmp_path / "tlog"),
    )
    router = Router(cfg, params=params)
    router.start()
    return router, params


def _port(router: Router, i: int) -> int:
    addr = router.endpoints[i].link.local_address
    assert addr is not None
    return addr[1]


@pytest.fixture()
def tmp_key(tmp_path: Path) -> Iterator[tuple[Path, bytes]]:
    key = bytes(range(100, 132))
    path = tmp_path / "signing.key"
    path.write_text(key.hex() + "\n")
    os.chmod(path, stat.S_IRUSR | stat.S_IWUSR)
    yield path, key


@pytest.mark.skipif(not SMALL_TLOG.exists(), reason=f"corpus capture {SMALL_TLOG} is absent")
def test_ardusub_dive_replayed_through_the_bridge_byte_for_byte(tmp_path: Path) -> None:
    records = list(mio.iter_tlog(SMALL_TLOG))
    router, _ = _router(tmp_path)
    gcs = mio.MavEndpoint(
        f"udpout:127.0.0.1:{_port(router, 1)}", source_system=GCS_ID[0], source_component=GCS_ID[1]
    )
    autopilot = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    autopilot.bind(("127.0.0.1", 0))
    try:
        gcs.send_heartbeat()  # the GCS is seen: (255, 190) and its address
        _wait(lambda: router.endpoints[1].link.has_peer(), "the GCS to be seen")
        # The oracle: what mavlink-router's rule lets through to a GCS that has seen only
        # itself. Bad-CRC packets never pass; messages addressed to system 1 (the GCS's own
        # commands recorded in the dive) have no route back towards a GCS.
        seen_sys, seen = {GCS_ID[0]}, {GCS_ID}
        expected: list[bytes] = []
        batches: list[int] = []
        camera = 0
        framer = MavFramer()
        offsets = mio.target_offsets()
        for r in records:
            frames = framer.feed(r.raw, boundary=True)
            ok = False
            for f in frames:
                t = frame_target(f, offsets)
                ok = (f.sysid, f.compid) not in seen and (  # loop guard
                    t is None
                    or t[0] == 0
                    or (t[1] == 0 and t[0] in seen_sys)
                    or (t[0], t[1]) in seen
                )
            batches.append(len(expected))
            if frames and ok and r.msg is None:
                camera += 1  # forwarded, but pymavlink (the GCS here) refuses its CRC too
            elif frames and ok:
                expected.append(r.raw)
        # The 4 camera packets (259/260/262/269), CRC computed before the trailing zeros were
        # cut, are checked over the padded payload and pass, as through mavlink-router. The
        # GCS's own 1 767 packets recorded in the dive do not go back to it (loop guard): 267
        # of them were broadcasts that did.
        assert framer.stats.bad_crc == 0 and framer.stats.crc_untruncated == 4
        n_valid = sum(r.msg is not None for r in records)
        assert (len(records), n_valid, len(expected)) == (35_916, 35_912, 34_412 - 267)

        got: list[bytes] = []
        own: list[bytes] = []

        def pump(n: int) -> Callable[[], bool]:
            def done() -> bool:
                while True:
                    msg = gcs.recv(timeout_s=0.0)
                    if msg is None:
                        return len(got) >= n
                    raw = bytes(msg.get_msgbuf())
                    if (msg.get_srcSystem(), msg.get_srcComponent()) == (1, 191):
                        own.append(raw)
                    else:
                        got.append(raw)

            return done

        window = 200  # flow control by acknowledgement, not by time: no loss, no sleeps
        for start in range(0, len(records), window):
            for r in records[start : start + window]:
                autopilot.sendto(r.raw, ("127.0.0.1", _port(router, 0)))
            upto = start + window
            n = batches[upto] if upto < len(batches) else len(expected)
            _wait(pump(n), f"the GCS to receive {n} packets")
        assert got == expected  # byte for byte, in order, nothing more
        assert camera == 4
        _wait(lambda: gcs.recv(0.0) is None and gcs.bad_packets >= camera, "camera packets", 2.0)
        assert gcs.bad_packets == camera  # they did arrive (pymavlink's dialect refuses them)
        # The last records are ones nothing is forwarded for: the GCS's count cannot tell that
        # the router has read them (CI once read the summary one packet early).
        _wait(lambda: router.summary()["autopilot"]["rx_packets"] >= 35_916,
              "the router to read every packet")
        s = router.summary()
        assert s["bad_crc"] == 0 and s["dropped_bytes"] == 0 and s["unchecked"] == 0
        assert s["autopilot"]["rx_packets"] == 35_916
        assert s["gcs0"]["loop_guard"] == 1_767
        # 1 500 packets addressed to system 1: 1 499 have no route, and one, the GCS's
        # PARAM_REQUEST_LIST to (1, 0), is for every component of system 1: the bridge answers.
        # The GCS's 267 broadcasts have nowhere to go but back to it (loop guard).
        assert s["autopilot"]["unroutable"] == 1_499 and s["for_bridge"] == 1
        assert s["no_destination"] >= 267
        assert s["gcs0"]["dropped_queue_full"] == 0
        # The bridge's own packets (its heartbeat, its answer to PARAM_REQUEST_LIST) come from
        # the router thread, which a loaded machine may schedule late: wait for them, bounded.
        drain = pump(len(expected))
        _wait(lambda: drain() and bool(own), "the bridge's own packets", 5.0)
        assert own and all(mio.decode_packet(p) is not None for p in own)
        kinds = {mio.decode_packet(p).get_type() for p in own}
        assert "HEARTBEAT" in kinds
        assert s["gcs0"]["tx_packets"] >= len(expected) + len(own)
    finally:
        router.close()
        gcs.close()
        autopilot.close()
    # The recorder saw every framed packet once plus the bridge's own.
    tlogs = sorted((tmp_path / "tlog").glob("*.tlog"))
    recorded = [r.raw for p in tlogs for r in mio.iter_tlog(p)]
    assert len(recorded) >= 35_912 + 1  # + GCS heartbeat and own packets


def _param_value(ep: mio.MavEndpoint, name: str, deadline_s: float = 5.0) -> float | None:
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        msg = ep.recv(timeout_s=0.2)
        if msg is not None and msg.get_type() == "PARAM_VALUE" and msg.param_id == name:
            return float(msg.param_value)
    return None


def test_param_protocol_list_read_set_and_override_file(tmp_path: Path) -> None:
    router, params = _router(tmp_path)
    gcs = mio.MavEndpoint(f"udpout:127.0.0.1:{_port(router, 1)}", source_system=255)
    changes: list[tuple[str, float]] = []
    params.on_change(lambda n, v: changes.append((n, v)))
    try:
        gcs.send_heartbeat()
        gcs.send_param_request_list(1, 191)
        seen = {}
        end = time.monotonic() + 5.0
        while len(seen) < 2 and time.monotonic() < end:
            msg = gcs.recv(timeout_s=0.2)
            if msg is not None and msg.get_type() == "PARAM_VALUE":
                seen[msg.param_id] = (msg.param_value, msg.param_index, msg.param_count)
        assert seen["FDI_ALPHA"][1:] == (0, 2) and seen["FDI_WINDOW"][1:] == (1, 2)
        gcs.send_param_set(1, 191, "FDI_WINDOW", 42.0)
        assert _param_value(gcs, "FDI_WINDOW") == 42.0
        assert params.get("FDI_WINDOW") == 42.0 and changes == [("FDI_WINDOW", 42.0)]
        gcs.send_param_set(1, 191, "FDI_WINDOW", 1e6)  # out of bounds: refused, old value back
        assert _param_value(gcs, "FDI_WINDOW") == 42.0
        gcs.send_param_request_read(1, 191, "FDI_ALPHA")
        assert _param_value(gcs, "FDI_ALPHA") == pytest.approx(0.05)
    finally:
        router.close()
        gcs.close()
    text = (tmp_path / "params.toml").read_text()
    assert "FDI_WINDOW = 42.0" in text and "FDI_ALPHA" not in text
    again = ParamStore(tmp_path / "params.toml")
    assert again.register(ParamSpec("FDI_WINDOW", 20.0, 1.0, 500.0)) == 42.0


def test_signing_signed_gcs_sets_unsigned_cannot(
    tmp_path: Path, tmp_key: tuple[Path, bytes]
) -> None:
    key_file, key = tmp_key
    assert load_signing_key(key_file) == key
    router, params = _router(tmp_path, signing=True, key_file=key_file)
    port = _port(router, 1)
    signed = mio.MavEndpoint(f"udpout:127.0.0.1:{port}", source_system=255, source_component=190)
    signed.setup_signing(key, link_id=1)
    unsigned = mio.MavEndpoint(f"udpout:127.0.0.1:{port}", source_system=254)
    wrong = mio.MavEndpoint(f"udpout:127.0.0.1:{port}", source_system=253)
    wrong.setup_signing(bytes(32), link_id=2)
    try:
        for ep in (signed, unsigned, wrong):
            ep.send_heartbeat()  # unsigned and wrongly signed heartbeats are refused too
        unsigned.send_param_set(1, 191, "FDI_ALPHA", 0.2)
        wrong.send_param_set(1, 191, "FDI_ALPHA", 0.3)
        _wait(lambda: router.stats.refused_unsigned + router.stats.bad_signature == 4,
              "four refusals")
        assert params.get("FDI_ALPHA") == 0.05
        assert router.stats.bad_signature == 2 and router.stats.refused_unsigned == 2
        signed.send_param_set(1, 191, "FDI_ALPHA", 0.01)
        assert _param_value(signed, "FDI_ALPHA") == pytest.approx(0.01)
        assert params.get("FDI_ALPHA") == pytest.approx(0.01)
        # Reads stay open to an unsigned GCS.
        unsigned.send_param_request_read(1, 191, "FDI_ALPHA")
        assert _param_value(unsigned, "FDI_ALPHA") == pytest.approx(0.01)
        assert router.stats.refused_unsigned == 2
    finally:
        router.close()
        for ep in (signed, unsigned, wrong):
            ep.close()


def test_signing_key_file_rules(tmp_path: Path) -> None:
    from fdi.errors import ConfigError

    path = tmp_path / "k"
    path.write_text("00" * 32)
    os.chmod(path, 0o644)
    with pytest.raises(ConfigError, match="owner"):
        load_signing_key(path)
    os.chmod(path, 0o600)
    assert load_signing_key(path) == bytes(32)
    path.write_text("zz")
    with pytest.raises(ConfigError, match="hexadecimal"):
        load_signing_key(path)
    inside = ROOT / "tests"  # a git working tree: refused even with a good key and mode
    assert (ROOT / ".git").exists()
    with pytest.raises(ConfigError):
        load_signing_key(inside / "no-such.key")


def test_flood_on_gcs_side_does_not_stall_the_autopilot_direction(tmp_path: Path) -> None:
    """A flood on the GCS link (>> 10 000 packets/s) while the autopilot talks and the detector
    hands fixes over: the autopilot's packets reach the GCS, every fix reaches the autopilot,
    and handing one over never waits on a socket."""
    router, _ = _router(tmp_path)
    gcs = mio.MavEndpoint(f"udpout:127.0.0.1:{_port(router, 1)}", source_system=255)
    # The autopilot stand-in: a raw socket read by its own thread.
    ap = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ap.bind(("127.0.0.1", 0))
    ap.settimeout(0.05)
    gps_id = mio.message_id("GPS_INPUT")
    gps: list[bytes] = []
    halt = threading.Event()

    def ap_reader() -> None:
        while not halt.is_set():
            with contextlib.suppress(TimeoutError):
                data = ap.recv(65535)
                if data[0] == 0xFD and data[7] == gps_id:
                    gps.append(data)

    reader = threading.Thread(target=ap_reader, daemon=True)
    reader.start()
    ap_packer = mio.MavPacker(1, 1)
    flood = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        gcs.send_heartbeat()
        ap.sendto(ap_packer.send_heartbeat(), ("127.0.0.1", _port(router, 0)))
        _wait(lambda: router.endpoints[0].link.has_peer(), "autopilot peer")
        # Addressed to a system nobody has shown: the router reads, frames and routes every
        # one (and counts it unroutable), while the stand-in's own socket is not flooded.
        # (A flood that is forwarded is the benchmark's 10 000 packets/s case.)
        junk = mio.MavPacker(255, 190).send_param_request_read(77, 1, "FLOOD")
        fix = mio.GpsInputFix(0, 2000, 0, 3, 32.0, 118.0, 10.0, 0.9, None, None, None, None,
                              0.1, 0.5, 1.0, 10)  # fmt: skip
        t_end = time.monotonic() + 1.0
        n = 0
        handed: list[float] = []  # how long the detector's thread spends handing a fix over
        while time.monotonic() < t_end:  # as fast as one thread can: >> 10 000 packets/s
            flood.sendto(junk, ("127.0.0.1", _port(router, 1)))
            n += 1
            if n % 500 == 0:
                ap.sendto(ap_packer.send_statustext(6, f"ap {n}"), ("127.0.0.1", _port(router, 0)))
                t0 = time.perf_counter()
                router.send_gps_input(fix)  # the detector's output, during the flood
                handed.append(time.perf_counter() - t0)
        ap.sendto(ap_packer.send_statustext(6, "last"), ("127.0.0.1", _port(router, 0)))
        end = time.monotonic() + 5.0
        texts = []
        while time.monotonic() < end and ("last" not in texts or len(gps) < len(handed)):
            msg = gcs.recv(timeout_s=0.01)
            if msg is not None and msg.get_type() == "STATUSTEXT":
                texts.append(msg.text)
        assert "last" in texts
        assert n > 10_000
        s = router.summary()
        assert s["gcs0"]["unroutable"] > 10_000  # the router did take the flood
        assert len(gps) == len(handed) >= 10, s  # every fix reached the autopilot
        # Handing a fix over never waits on a socket; in one process it may wait for the GIL
        # (the switch interval is 5 ms), well inside a 10 Hz receiver's 100 ms period.
        assert max(handed) < 0.05
    finally:
        halt.set()
        reader.join(timeout=2.0)
        router.close()
        gcs.close()
        ap.close()
        flood.close()


MAVPROXY = Path(sys.executable).parent / "mavproxy.py"


@pytest.mark.skipif(
    not MAVPROXY.exists(), reason="MAVProxy is not installed (pip install MAVProxy)"
)
def test_mavproxy_sees_heartbeat_lists_and_sets_a_parameter(tmp_path: Path) -> None:
    import subprocess
    import sys

    from firmware_host.devtools.rover_sim import RoverScenario, write_run
    from firmware_host.rover.mavlink import attach_rover
    from firmware_host.rover.pipeline import RoverPipeline
    from firmware_host.runtime.config import RoverConfig

    params = ParamStore(tmp_path / "params.toml")
    router = Router(
        MavlinkConfig(
            autopilot=EndpointConfig("udpin:127.0.0.1:0"),
            gcs=(EndpointConfig("udpin:127.0.0.1:0"),),
        ),
        params=params,
    )
    pipeline = RoverPipeline(RoverConfig())
    attach_rover(pipeline, router)  # the rover detector's thresholds are the parameters
    n_params = len(params)
    assert params.get("FDI_WINDOW") == 12.0 and n_params >= 10
    router.start()
    cmd = [
        sys.executable, str(MAVPROXY), f"--master=udpout:127.0.0.1:{_port(router, 1)}",
        "--target-system=1", "--target-component=191", "--source-system=255", "--nowait",
        f"--state-basedir={tmp_path / 'mavproxy'}", "--default-modules=param",
    ]  # fmt: skip
    (tmp_path / "mavproxy").mkdir()
    proc = subprocess.Popen(
        cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    assert proc.stdin is not None and proc.stdout is not None
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")),  # type: ignore[union-attr]
                              daemon=True)  # fmt: skip
    reader.start()
    try:
        # MAVProxy fetches the parameter list of the component it targets once it has seen
        # its heartbeat; once it says it has them all, "param set" is retried until the
        # bridge's store shows the value.
        _wait(lambda: any(f"Received {n_params} parameters" in x for x in list(lines)),
              f"MAVProxy to receive the {n_params} parameters", 20.0)  # fmt: skip
        next_try = 0.0

        def set_param() -> bool:
            nonlocal next_try
            if time.monotonic() >= next_try:
                proc.stdin.write("param show FDI*\nparam set FDI_WINDOW 33\n")  # type: ignore[union-attr]
                proc.stdin.flush()  # type: ignore[union-attr]
                next_try = time.monotonic() + 0.5
            return params.get("FDI_WINDOW") == 33.0

        _wait(set_param, "MAVProxy to set FDI_WINDOW", 20.0)
    finally:
        with contextlib.suppress(OSError):
            proc.stdin.close()  # MAVProxy's console thread ends with its input
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)
        reader.join(timeout=5)
        router.close()
    out = "".join(lines)
    assert "Detected vehicle 1:191" in out  # our heartbeat
    assert f"Received {n_params} parameters" in out
    assert "FDI_ALPHA" in out and "FDI_WINDOW" in out
    assert router.stats.params_set >= 1
    # The detector uses the new value from its next epoch: a 33-epoch grey window.
    assert pipeline.isolator.p.window == 12
    write_run(RoverScenario(rate_hz=1.0, duration_s=5.0, seed=1), tmp_path / "run")
    assert pipeline.feed((tmp_path / "run" / "rover.nmea").read_bytes()) >= 4
    assert pipeline.isolator.p.window == 33
    assert pipeline.isolator._win.maxlen == 33
    assert "FDI_WINDOW = 33.0" in (tmp_path / "params.toml").read_text()


@pytest.mark.skipif(not SMALL_TLOG.exists(), reason=f"corpus capture {SMALL_TLOG} is absent")
def test_ground_station_side_of_the_dive_reaches_the_autopilot_and_tlogs_rotate(
    tmp_path: Path,
) -> None:
    """The GCS's own 1 767 packets of the dive, played from the GCS side, reach the autopilot.

    The autopilot stand-in has shown the components the GCS addresses (1:1 the autopilot, 1:100
    the camera manager, 1:194 and 1:220 as in the dive), so every packet has a route. The tlog
    is rotated at 16 KiB and its files, read in order, hold exactly what went through.
    """
    from drivers.mavlink.framer import MavFramer

    records = [r for r in mio.iter_tlog(SMALL_TLOG) if r.msg is not None]
    from_gcs = [r.raw for r in records if (r.msg.get_srcSystem(), r.msg.get_srcComponent())
                == GCS_ID]  # fmt: skip
    assert len(from_gcs) == 1_767
    params = ParamStore()
    cfg = MavlinkConfig(
        autopilot=EndpointConfig("udpin:127.0.0.1:0"),
        gcs=(EndpointConfig("udpin:127.0.0.1:0"),),
        tlog_dir=str(tmp_path / "tlog"),
        tlog_max_bytes=16 * 1024,
        stats_hz=0.0,
    )
    router = Router(cfg, params=params)
    router.start()
    ap = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ap.bind(("127.0.0.1", 0))
    ap.settimeout(0.0)
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    hello = [mio.MavPacker(1, c).send_heartbeat() for c in (1, 100, 194, 220)]
    got: list[bytes] = []
    own: list[bytes] = []
    framer = MavFramer()

    def pump(n: int) -> Callable[[], bool]:
        def done() -> bool:
            while True:
                try:
                    data = ap.recv(65535)
                except BlockingIOError:
                    return len(got) >= n
                for f in framer.feed(data, boundary=True):
                    (own if (f.sysid, f.compid) == (1, 191) else got).append(f.raw)

        return done

    try:
        for raw in hello:
            ap.sendto(raw, ("127.0.0.1", _port(router, 0)))
        _wait(lambda: router.endpoints[0].seen.keys() >= {(1, 1), (1, 100), (1, 194), (1, 220)},
              "the autopilot's components")  # fmt: skip
        window = 100
        for start in range(0, len(from_gcs), window):
            for raw in from_gcs[start : start + window]:
                gcs.sendto(raw, ("127.0.0.1", _port(router, 1)))
            n = min(start + window, len(from_gcs))
            _wait(pump(n), f"the autopilot to receive {n} packets")
        s = router.summary()
    finally:
        router.close()
        ap.close()
        gcs.close()
    assert got == from_gcs  # byte for byte, in order, each once
    assert s["gcs0"]["rx_packets"] == 1_767 and s["gcs0"]["unroutable"] == 0
    assert s["for_bridge"] == 1  # the PARAM_REQUEST_LIST to (1, 0): nothing to list, no answer
    assert s["autopilot"]["dropped_queue_full"] == 0 and s["bad_crc"] == 0
    # Rotation by size: several files, none over the limit, together everything in order.
    assert router.tlog is not None
    files = router.tlog.files  # in the order written
    assert sorted(files) == sorted((tmp_path / "tlog").glob("*.tlog"))
    assert len(files) >= 3  # ~60 kB of packets and stamps
    assert all(f.stat().st_size <= 16 * 1024 for f in files)
    recorded = [r.raw for f in files for r in mio.iter_tlog(f)]
    passed = [p for p in recorded if p not in hello]
    through = [p for p in passed if mio.decode_packet(p).get_srcSystem() == 255]
    assert through == from_gcs
    stamps = [r.t_us for f in files for r in mio.iter_tlog(f)]
    assert stamps == sorted(stamps)


def test_tcp_links_ground_station_server_and_autopilot_client(tmp_path: Path) -> None:
    """A GCS on a TCP server link (``tcpin:``), the autopilot on a TCP client link (``tcp:``,
    as SITL listens on 5760): byte streams framed across segment boundaries, both ways."""
    from drivers.mavlink.framer import MavFramer

    listener = socket.create_server(("127.0.0.1", 0))
    ap_port = listener.getsockname()[1]
    params = ParamStore()
    params.register(ParamSpec("FDI_ALPHA", 0.05, 1e-6, 0.5))
    cfg = MavlinkConfig(
        autopilot=EndpointConfig(f"tcp:127.0.0.1:{ap_port}"),
        gcs=(EndpointConfig("tcpin:127.0.0.1:0"),),
        stats_hz=0.0,
    )
    router = Router(cfg, params=params)
    ap, _ = listener.accept()
    listener.close()
    router.start()
    gcs = mio.MavEndpoint(f"tcp:127.0.0.1:{_port(router, 1)}", source_system=255,
                          source_component=190)  # fmt: skip
    try:
        _wait(lambda: router.endpoints[1].link.has_peer(), "the TCP ground station")
        packer = mio.MavPacker(1, 1)
        sent = [packer.send_heartbeat() if i % 10 == 0 else packer.send_statustext(6, f"ap {i}")
                for i in range(500)]  # fmt: skip
        stream = b"".join(sent)
        for i in range(0, len(stream), 997):  # segments that cut packets anywhere
            ap.sendall(stream[i : i + 997])
        got: list[bytes] = []

        def from_ap() -> bool:
            msg = gcs.recv(timeout_s=0.05)
            if msg is not None and msg.get_srcComponent() == 1:
                got.append(bytes(msg.get_msgbuf()))
            return len(got) >= len(sent)

        _wait(from_ap, "500 packets over TCP")
        assert got == sent
        # GCS -> bridge (parameter protocol) and GCS -> autopilot (a command) over TCP.
        gcs.send_param_request_read(1, 191, "FDI_ALPHA")
        assert _param_value(gcs, "FDI_ALPHA") == pytest.approx(0.05)
        cmd = mio.MavPacker(255, 190).send_command_ack(400, 0, 1, 1)
        gcs.send_raw(cmd)
        framer = MavFramer()
        seen: list[bytes] = []
        ap.settimeout(0.05)

        def at_ap() -> bool:
            with contextlib.suppress(TimeoutError):
                seen.extend(f.raw for f in framer.feed(ap.recv(65535)))
            return any(f.startswith(cmd[:3]) and f[5:] == cmd[5:] for f in seen)

        _wait(at_ap, "the GCS's packet at the autopilot")
        assert router.summary()["gcs0"]["link_errors"] == 0
    finally:
        router.close()
        gcs.close()
        ap.close()


def test_tcp_client_link_reconnects_when_the_server_restarts(tmp_path: Path) -> None:
    """SITL (a TCP server on 5760) is restarted: the router's ``tcp:`` link counts the loss,
    connects again by itself to the same port, and the autopilot's packets reach the GCS."""
    listener = socket.create_server(("127.0.0.1", 0))
    ap_port = listener.getsockname()[1]
    cfg = MavlinkConfig(
        autopilot=EndpointConfig(f"tcp:127.0.0.1:{ap_port}"),
        gcs=(EndpointConfig("udpin:127.0.0.1:0"),),
        stats_hz=0.0,
        reconnect_max_s=0.2,
    )
    router = Router(cfg)
    ap, _ = listener.accept()
    listener.close()
    router.start()
    gcs = mio.MavEndpoint(f"udpout:127.0.0.1:{_port(router, 1)}", source_system=255,
                          source_component=190)  # fmt: skip
    packer = mio.MavPacker(1, 1)
    link = router.endpoints[0].link

    def heartbeat_reaches_gcs(sock: socket.socket) -> bool:
        sock.sendall(packer.send_heartbeat())
        msg = gcs.recv(timeout_s=0.02)
        while msg is not None:
            if (msg.get_srcSystem(), msg.get_srcComponent()) == (1, 1):
                return True
            msg = gcs.recv(0.0)
        return False

    ap2: socket.socket | None = None
    try:
        gcs.send_heartbeat()
        _wait(lambda: heartbeat_reaches_gcs(ap), "the autopilot's heartbeat")
        ap.close()  # SITL stops ...
        _wait(lambda: link.errors == 1 and not link.has_peer(), "the loss")
        listener = socket.create_server(("127.0.0.1", ap_port))  # ... and starts again
        listener.settimeout(10.0)
        ap2, _ = listener.accept()
        listener.close()
        sock2 = ap2
        _wait(lambda: heartbeat_reaches_gcs(sock2), "the heartbeat after the restart")
        assert getattr(link, "reconnects", None) == 1
        assert router._thread is not None and router._thread.is_alive()
    finally:
        router.close()
        gcs.close()
        ap.close()
        if ap2 is not None:
            ap2.close()


PASSPHRASE = "fdiBridgeTest42"  # MAVProxy's `signing key/setup` takes one word (first only)


@pytest.mark.skipif(
    not MAVPROXY.exists(), reason="MAVProxy is not installed (pip install MAVProxy)"
)
def test_documented_mavproxy_signing_commands_set_a_parameter(tmp_path: Path,
                                                          key_dir: Path) -> None:
    """docs/mavlink.md's recipe: the key file from ``sha256(passphrase)``, MAVProxy's
    ``signing key PASSPHRASE``; MAVProxy's signed PARAM_SET is accepted on a signing link."""
    import hashlib
    import subprocess

    key_file = key_dir / "signing.key"
    # The documented command: printf '%s' PASSPHRASE | sha256sum | cut -d' ' -f1 > FILE
    out = subprocess.run(f"printf '%s' '{PASSPHRASE}' | sha256sum | cut -d' ' -f1",
                         shell=True, capture_output=True, text=True, check=True).stdout
    key_file.write_text(out)
    os.chmod(key_file, 0o600)
    assert load_signing_key(key_file) == hashlib.sha256(PASSPHRASE.encode()).digest()
    params = ParamStore(tmp_path / "params.toml")
    params.register(ParamSpec("FDI_ALPHA", 0.05, 1e-6, 0.5))
    params.register(ParamSpec("FDI_WINDOW", 12.0, 1.0, 500.0, integer=True))
    router = Router(MavlinkConfig(
        autopilot=EndpointConfig("udpin:127.0.0.1:0"),
        gcs=(EndpointConfig("udpin:127.0.0.1:0", signing=True),),
        signing_key_file=str(key_file), signing_state_file=str(tmp_path / "sig.state"),
    ), params=params)
    router.start()
    cmd = [
        sys.executable, str(MAVPROXY), f"--master=udpout:127.0.0.1:{_port(router, 1)}",
        "--target-system=1", "--target-component=191", "--source-system=255", "--nowait",
        f"--state-basedir={tmp_path / 'mavproxy'}", "--default-modules=param,signing",
    ]  # fmt: skip
    (tmp_path / "mavproxy").mkdir()
    env = dict(os.environ, HOME=str(tmp_path))  # no ~/.mavproxy/signing.keys of the user's
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env)
    assert proc.stdin is not None and proc.stdout is not None
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")),  # type: ignore[union-attr]
                              daemon=True)  # fmt: skip
    reader.start()
    try:
        proc.stdin.write(f"signing key {PASSPHRASE}\n")
        proc.stdin.flush()
        next_try = 0.0

        def set_param() -> bool:
            nonlocal next_try
            if time.monotonic() >= next_try:
                proc.stdin.write("param set FDI_WINDOW 33\n")  # type: ignore[union-attr]
                proc.stdin.flush()  # type: ignore[union-attr]
                next_try = time.monotonic() + 0.5
            return params.get("FDI_WINDOW") == 33.0

        _wait(set_param, "MAVProxy's signed PARAM_SET", 20.0)
    finally:
        with contextlib.suppress(OSError):
            proc.stdin.close()
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)
        reader.join(timeout=5)
        router.close()
    s = router.summary()
    # Accepted although the link refuses every unsigned PARAM_SET: MAVProxy signed it.
    assert s["params_set"] >= 1 and s["bad_signature"] == 0


@pytest.mark.skipif(
    not MAVPROXY.exists(), reason="MAVProxy is not installed (pip install MAVProxy)"
)
def test_mavproxy_with_ftp_gets_the_parameter_list_without_waiting(tmp_path: Path) -> None:
    """MAVProxy with its ftp module first asks for ``@PARAM/param.pck`` by MAVLink FTP; the
    bridge's NAK makes it fall back to PARAM_REQUEST_LIST at once, not after its timeout."""
    import subprocess

    params = ParamStore(tmp_path / "params.toml")
    for i in range(5):
        params.register(ParamSpec(f"FDI_P{i}", float(i), -10.0, 10.0))
    router = Router(MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"),
                                  gcs=(EndpointConfig("udpin:127.0.0.1:0"),)), params=params)
    router.start()
    cmd = [
        sys.executable, str(MAVPROXY), f"--master=udpout:127.0.0.1:{_port(router, 1)}",
        "--target-system=1", "--target-component=191", "--source-system=255", "--nowait",
        f"--state-basedir={tmp_path / 'mavproxy'}", "--default-modules=param,ftp",
    ]  # fmt: skip
    (tmp_path / "mavproxy").mkdir()
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True,
                            env=dict(os.environ, HOME=str(tmp_path)))
    assert proc.stdin is not None and proc.stdout is not None
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")),  # type: ignore[union-attr]
                              daemon=True)  # fmt: skip
    reader.start()
    try:
        _wait(lambda: any("Received 5 parameters" in x for x in list(lines)),
              "MAVProxy to receive the 5 parameters", 30.0)
        took = time.monotonic() - t0
    finally:
        with contextlib.suppress(OSError):
            proc.stdin.close()
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)
        reader.join(timeout=5)
        router.close()
    assert router.stats.ftp_nak >= 1, "".join(lines)
    assert "(ftp)" not in "".join(lines)  # by the parameter protocol, after the NAK
    # measured: 3.6 s with the NAK (MAVProxy start-up included), 13.6 s without (its timeout)
    assert took < 10.0, f"{took:.1f} s"
