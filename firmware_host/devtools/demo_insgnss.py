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
while the vehicle runs), so that a successful demo prints no WARNING; so is the INS's coasting
through an ``--outage`` (its check is printed).

``--gyro-drift`` gives the autopilot's gyros ArduPilot's simulated drift (``SIM_DRIFT_SPEED``,
0.05 deg/s per minute) and an ATTITUDE stream (1 deg off: the heading at rest of a MEMS gyro);
``--outage START,LENGTH`` cuts the GNSS. With the live example's filter (``--config
config/insgnss-live-example.toml``, ``--imu RAW_IMU``, ``--rest 200``, ``--outage 140,20``) it
is issue G's check: every coast epoch within twice the accuracy sent, then no-fix.
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
    parser.add_argument("--gyro-drift", type=float, default=0.0, metavar="DEG_S_PER_MIN",
                        help="the autopilot's gyros drift this fast on every axis, as "
                             "ArduPilot's simulated IMU (SIM_DRIFT_SPEED: 0.05; up to 0.25 "
                             "deg/s); with the live example's filter (--config "
                             "insgnss-live-example) the filter models it")
    parser.add_argument("--outage", default=None, metavar="START,LENGTH",
                        help="a GNSS outage LENGTH s long from START s after the data's "
                             "start (120,20 with --rest 200: at rest, after the alignment); "
                             "prints the coast's check")
    parser.add_argument("--config", type=input_file_arg, default=None,
                        help=f"INS/GNSS preset (default {PAPER_PRESET.name})")
    parser.add_argument("--out", type=output_dir_arg, default=Path("insgnss-demo"),
                        help="directory for the vehicle's epochs.jsonl and summary.json")


def _outage(text: str | None, lead_s: float) -> tuple[float, float] | None:
    """``START,LENGTH`` (seconds from the data's start) as trajectory times (t = 0 at the end
    of the lead-in)."""
    if text is None:
        return None
    try:
        start, length = (float(x) for x in text.split(","))
    except ValueError:
        raise ConfigError("demo insgnss", "--outage", "START,LENGTH (seconds)",
                          repr(text)) from None
    if not (start >= 0.0 and length > 0.0):
        raise ConfigError("demo insgnss", "--outage", "START >= 0, LENGTH > 0", repr(text))
    return start - lead_s, start + length - lead_s


def run(args: argparse.Namespace) -> int:
    if args.epochs < 20 or args.rest < 0 or not args.speed > 0:
        raise ConfigError("demo insgnss", "--epochs/--rest/--speed",
                          "epochs >= 20, rest >= 0, speed > 0",
                          f"{args.epochs}, {args.rest}, {args.speed}")
    if not args.gyro_drift >= 0.0:
        raise ConfigError("demo insgnss", "--gyro-drift", "deg/s per minute >= 0",
                          str(args.gyro_drift))
    base = load_setup(args.config)
    setup = replace(base, sim=replace(
        base.sim, epochs=args.epochs, rest_s=args.rest,
        random_faults=round(base.sim.random_faults * (args.epochs - 1) / 500),
        gyro_drift_deg_s_per_min=args.gyro_drift or base.sim.gyro_drift_deg_s_per_min))
    impair = LinkImpairment(drop=0.1, duplicate=0.01, burst_every_s=2.0,
                            shuffle_bursts=True) if args.impaired else None
    out = Path(args.out)
    lead = setup.sim.lead_s
    outage = _outage(args.outage, lead)
    print(f"simulated autopilot: {args.scenario}, seed {args.seed}, {args.epochs} epochs after "
          f"{lead} s of lead-in, {args.imu} at {setup.sim.imu_rate_hz} Hz on a pty, NMEA on "
          f"another, {args.speed:g}x real time{'; impaired IMU link' if impair else ''}")
    with MavEndpoint("udpin:127.0.0.1:0") as rx:
        addr = rx.local_address
        assert addr is not None
        with expected_quiet(EXPECTED_LOGGERS + (("fdi_bridge.insgnss",) if outage else ())):
            c = compare(setup, args.scenario, args.seed, out, speed=args.speed,
                        imu_message=args.imu, impair=impair, outage=outage,
                        attitude_error_deg=1.0 if args.gyro_drift else None,
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
    cr = c.run.coast
    if cr is not None and outage is not None:
        print(f"GNSS outage {outage[0] + lead:g}..{outage[1] + lead:g} s: the INS's coast "
              f"sent as 3D fixes {cr.sent} epochs (true error at most {cr.worst_ratio:.2f}x "
              f"the accuracy sent, {cr.worst_err_m:.2f} m), then no-fix {cr.no_fix} epochs "
              f"({ins.get('coast_failed', 0)} coast claims failed)")
    print()
    print(table(COMPARISON_HEADER, [c.row()]))
    print(f"\nwrote {out / 'epochs.jsonl'} and {out / 'summary.json'}")
    return 0
