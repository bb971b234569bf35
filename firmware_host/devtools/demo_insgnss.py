"""``fdi-bridge demo insgnss``: the live INS/GNSS vehicle against a simulated autopilot, end to
end, compared with the offline filter of ``fdi-bridge sim insgnss``.

The simulated autopilot (:mod:`firmware_host.devtools.insgnss_live`) plays a paper scenario
(same generator and seed as ``sim insgnss``), starting like a real vehicle: ``--rest`` seconds
at rest, a 20 s take-off roll, then the paper's flight. Its IMU goes out as MAVLink on one
pty, its GNSS as NMEA on another; the vehicle (``firmware_host.insgnss.vehicle``, on the
runtime's Runner, as ``fdi-bridge run`` runs it) aligns itself, runs the filter and sends
GPS_INPUT to a UDP socket on 127.0.0.1, where the demo counts it. Printed: the live 3-D
position RMS over the paper's epochs against ``sim insgnss`` and "none" on the same data.

The scenario injects GPS faults, so the vehicle raises GPS alarms, its gate-health monitor sees
most of a fault's epochs flagged, and each alarm requests the alarm mode from a UDP socket that
is not an autopilot (no COMMAND_ACK comes). All of that is the demo working: it is counted on
the vehicle's line, and logged only at ``-v`` (:data:`EXPECTED_LOGGERS` are quiet below INFO
while the vehicle runs), so that a successful demo prints no WARNING.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

from drivers.mavlink.io import MavEndpoint
from fdi.errors import ConfigError
from firmware_host.commands.checks import input_file_arg, output_dir_arg
from firmware_host.commands.tables import table
from firmware_host.devtools.insgnss_live import COMPARISON_HEADER, LinkImpairment, compare
from firmware_host.devtools.insgnss_sim import PAPER_PRESET, SCENARIOS, load_setup

EXPECTED_LOGGERS = ("fdi_bridge.rover", "fdi_bridge.mavlink")


@contextlib.contextmanager
def expected_quiet(names: tuple[str, ...] = EXPECTED_LOGGERS) -> Iterator[None]:
    """Below ``-v``, the named loggers say only errors inside the block (the module docstring:
    the demo's own alarms are expected); at ``-v`` nothing changes."""
    if logging.getLogger().getEffectiveLevel() <= logging.INFO:
        yield
        return
    loggers = [logging.getLogger(n) for n in names]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.ERROR)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", choices=SCENARIOS, default="paper-single",
                        help="the paper scenario the simulated autopilot plays")
    parser.add_argument("--seed", type=int, default=1, help="random seed (as sim insgnss)")
    parser.add_argument("--epochs", type=int, default=501,
                        help="GNSS epochs of the paper's flight (at least 20)")
    parser.add_argument("--rest", type=int, default=120,
                        help="seconds at rest before the take-off roll (the vehicle's "
                             "alignment; 0: none, it then aligns in flight)")
    parser.add_argument("--speed", type=float, default=50.0,
                        help="times faster than real time the autopilot plays")
    parser.add_argument("--imu", choices=("HIGHRES_IMU", "RAW_IMU"), default="HIGHRES_IMU",
                        help="the IMU message the autopilot sends")
    parser.add_argument("--impaired", action="store_true",
                        help="an impaired telemetry link: 10 %% of the IMU packets dropped, "
                             "1 %% duplicated, 200 ms bursts every 2 s")
    parser.add_argument("--config", type=input_file_arg, default=None,
                        help=f"INS/GNSS preset (default {PAPER_PRESET.name})")
    parser.add_argument("--out", type=output_dir_arg, default=Path("insgnss-demo"),
                        help="directory for the vehicle's epochs.jsonl and summary.json")


def run(args: argparse.Namespace) -> int:
    if args.epochs < 20 or args.rest < 0 or not args.speed > 0:
        raise ConfigError("demo insgnss", "--epochs/--rest/--speed",
                          "epochs >= 20, rest >= 0, speed > 0",
                          f"{args.epochs}, {args.rest}, {args.speed}")
    base = load_setup(args.config)
    setup = replace(base, sim=replace(
        base.sim, epochs=args.epochs, rest_s=args.rest,
        random_faults=round(base.sim.random_faults * (args.epochs - 1) / 500)))
    impair = LinkImpairment(drop=0.1, duplicate=0.01, burst_every_s=2.0,
                            shuffle_bursts=True) if args.impaired else None
    out = Path(args.out)
    lead = setup.sim.lead_s
    print(f"simulated autopilot: {args.scenario}, seed {args.seed}, {args.epochs} epochs after "
          f"{lead} s of lead-in, {args.imu} at {setup.sim.imu_rate_hz} Hz on a pty, NMEA on "
          f"another, {args.speed:g}x real time{'; impaired IMU link' if impair else ''}")
    with MavEndpoint("udpin:127.0.0.1:0") as rx:
        addr = rx.local_address
        assert addr is not None
        with expected_quiet():
            c = compare(setup, args.scenario, args.seed, out, speed=args.speed,
                        imu_message=args.imu, impair=impair,
                        mavlink_url=f"udpout:127.0.0.1:{addr[1]}")
        gps_input = 0
        while (msg := rx.recv(timeout_s=0.2)) is not None:
            gps_input += msg.get_type() == "GPS_INPUT"
    ins = c.run.summary["ins"]
    a = ins.get("alignment") or {}
    print(f"vehicle: aligned by {a.get('method', 'nothing')} (1σ yaw "
          f"{a.get('sigma_yaw_deg', float('nan')):.3f} deg), {ins.get('zupts', 0)} ZUPTs at rest, "
          f"epochs {ins['epochs']}, IMU {ins['imu']}; {gps_input} GPS_INPUT received on "
          f"127.0.0.1:{addr[1]}; GPS alarms on the injected faults "
          f"{c.run.summary.get('alarms', 0)} (expected; -v logs them); {c.run.wall_s:.1f} s")
    print()
    print(table(COMPARISON_HEADER, [c.row()]))
    print(f"\nwrote {out / 'epochs.jsonl'} and {out / 'summary.json'}")
    return 0
