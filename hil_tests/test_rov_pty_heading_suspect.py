"""The driver's heading-rate flag end to end over a real pty on the runtime (issue 18).

The simulated vehicle streams on the pty's master side in real time (``serve_pty``); the bridge
runs ``run_rov`` (the Runner, ``OutlandRovVehicle``, ``link_step``, the controller) on the slave
path by URL. A three-sample 90 deg compass jump in the FIR's warm-up (where e^2 alone would not
open criterion 1) is flagged by the driver, opens a suspect, is substituted and not confirmed.

Three samples, not one: on RS-232 each period uses the newest frame waiting, so a bridge that
stalls 0.1 s (a loaded CI machine did, stop 25) reads a one-sample jump together with the next,
plausible frame and never uses the jump. That is the right behaviour, but it left this test
with nothing flagged to check; a 0.12 s stall at any step around the jump passes with three.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from drivers.outland.framecodec import load_protocol
from drivers.ptypair import PtyPair
from drivers.transport import SerialSettings
from firmware_host.devtools.rov_sim import RovPlant, RovSimServer, parse_fault, serve_pty
from firmware_host.rov.app import run_rov
from firmware_host.rov.config import LinkConfig, RovConfig

ROOT = Path(__file__).resolve().parent.parent
PROTO = load_protocol(ROOT / "config" / "protocols" / "outland1000.toml")


def test_flagged_jump_over_pty_is_substituted_not_confirmed() -> None:
    cfg = RovConfig(period_s=0.05)  # 20 Hz to keep it short: warm-up is 100 samples = 5 s
    with PtyPair() as pty:
        plant = RovPlant(cfg.sim, [parse_fault("spike:90@2-2.15")])  # three 20 Hz samples
        srv = RovSimServer(plant, PROTO, "rs232", node=1, period_s=cfg.period_s)
        stop = threading.Event()
        th = threading.Thread(target=serve_pty, args=(pty, srv, stop), daemon=True)
        th.start()
        link = LinkConfig(port=SerialSettings(url=pty.url, baudrate=115200), wiring="rs232")
        cfg = replace(cfg, link=link)
        epochs: list[dict[str, Any]] = []
        try:
            stats = run_rov(cfg, time.monotonic, time.sleep, base_dir=ROOT / "config",
                            max_steps=80, on_epoch=epochs.append)
        finally:
            stop.set()
            th.join(timeout=2.0)
    flagged = [e for e in epochs if e["heading_suspect"]]
    assert stats["counts"]["heading_suspect"] >= 1
    assert flagged, "the jump reached the bridge flagged"
    for e in flagged:
        assert e["suspect"] and e["source"] == "fir"
        # not steered on: the heading used is near the plausible readings around it
        k = epochs.index(e)
        prev = next(p["heading_meas"] for p in reversed(epochs[:k]) if not p["heading_suspect"])
        assert abs((e["heading_used"] - prev + 180.0) % 360.0 - 180.0) < 10.0
        assert abs((e["heading_meas"] - prev + 180.0) % 360.0 - 180.0) > 60.0
    assert not any(e["fault"] for e in epochs)
    assert all(e["event"] != "confirmed" for e in epochs)
